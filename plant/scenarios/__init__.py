"""Named simulation scenarios: the paper's section 4 and the planar cases users meet, and the spatial ones.
"""

from ._planar import (Scenario, SCENARIOS, get_scenario, PAPER_S, TABLE_1, draw_S, MAX_SAMPLES)
from ._spatial import (SpatialScenario, SPATIAL_SCENARIOS, TOOL, draw_spatial_S)

__all__ = ["Scenario", "get_scenario", "draw_S", "SpatialScenario", "draw_spatial_S"]
