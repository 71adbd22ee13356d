"""Named simulation scenarios: the paper's section 4 and the planar cases users meet, and the spatial ones;
and what a running robot adds to a log (another log of the same rig, a contact, a drifting offset).
"""

from ._planar import (Scenario, SCENARIOS, get_scenario, PAPER_S, TABLE_1, draw_S, MAX_SAMPLES)
from ._spatial import (SpatialScenario, SPATIAL_SCENARIOS, TOOL, draw_spatial_S)
from ._live import (DRIFT_SIZE, DRIFT_TAU, GRASP_RAMP, contact_wrench, drift_contact_log, same_rig, with_contact,
                    with_drift, with_grasp, with_push)

__all__ = ["Scenario", "get_scenario", "draw_S", "SpatialScenario", "draw_spatial_S",
           "same_rig", "contact_wrench", "with_contact", "with_push", "with_drift", "drift_contact_log",
           "with_grasp", "DRIFT_SIZE", "DRIFT_TAU", "GRASP_RAMP"]
