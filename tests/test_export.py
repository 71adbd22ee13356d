"""``fmscal export ros2-control``: a payload as ros2_control's broadcaster and gravity filter's parameters (issue 44).

The chain's arithmetic, written here from the C++ of ros2_controllers' force_torque_sensor_broadcaster
(``apply_sensor_offset``, then ``apply_sensor_multiplier``) and control_toolbox's GravityCompensation
(``update``: the gravity force turned into the sensor frame, subtracted from the force, its moment about
the CoG from the torque), run on simulated raw readings with the exported parameters read back from the
YAML by name: its output is the contact wrench, zero without contact, for both sign conventions. The names,
types and nesting the export writes are checked against the definition files of ROS 2 Jazzy's and
Kilted's releases, vendored in ``tests/data/ros2_control/``.
"""

import json
import re
import xml.etree.ElementTree as ElementTree
from pathlib import Path

import numpy as np
import pytest
import yaml

from fmscal.analysis import GRAVITY_FILTER, ROS2_CONTROL_RELEASES, ExportError, ros2_control_parameters
from fmscal.analysis._export import READ_ONLY, dynamics_left_out
from fmscal.analysis.cli import main
from fmscal.observers.payload import PayloadEstimate, fit_static
from fmscal.observers.payload._static_fit import _exp
from fmscal.plant import SPATIAL_SCENARIOS, Calibration
from fmscal.plant.io import simulate_table
from fmscal.plant.physics import SpatialPayload, quaternion_multiply, rotation_matrices, sensor_wrench, spatial_motion
from fmscal.plant.physics import edge
from fmscal.plant.scenarios import TOOL

DATA = Path(__file__).parent / "data" / "ros2_control"
RELEASES = ("jazzy", "kilted")
#: The broadcaster's channels in fmscal's reading order (tx ty tz fx fy fz).
NAMES = [("torque", "x"), ("torque", "y"), ("torque", "z"), ("force", "x"), ("force", "y"), ("force", "z")]
OFFSET = np.array([0.02, -0.01, 0.005, 0.4, -0.3, 0.6])                    # b, N m and N
GAINS = np.array([1.03, 0.98, 1.01, 0.95, 1.04, 1.02])
MOUNT = _exp(np.radians(6.0) * np.array([0.3, 1.0, 0.5]) / np.linalg.norm([0.3, 1.0, 0.5]))
G = _exp(np.radians(4.0) * np.array([1.0, 0.2, 0.0])) @ np.array([0.0, 0.0, -9.81])       # a tilted base
COM = np.array(TOOL.com)                                                    # sensor axes


def _attitudes(n, seed):
    rng = np.random.default_rng(seed)
    axes = rng.normal(size=(n, 3))
    angles = rng.uniform(0, np.pi, n)
    return np.array([_exp(a * v / np.linalg.norm(v)) for a, v in zip(angles, axes)])


def _estimate(reading, gains):
    """A payload as a fit reports it: the sensor's axes, the mounting, gravity estimated, the offset."""
    return PayloadEstimate(mass=TOOL.mass, mass_std=1e-3, com=COM, com_std=np.full(3, 1e-4), inertia=None,
                           inertia_std=None, b=OFFSET, b_std=np.full(6, 1e-3), residual_rms=np.zeros(6),
                           converged=True, payload_determined=True, gravity=G, gravity_std_deg=0.05, mounting=MOUNT,
                           mounting_deg=6.0, mounting_std_deg=0.05, reading=reading, gains=gains)


def _read_back(exported):
    """The broadcaster's parameters as a ROS 2 node gets them: the YAML written, parsed (PyYAML: YAML 1.1)."""
    document = yaml.safe_load(exported.to_yaml())
    (name, node), = document.items()
    return node["ros__parameters"]


def chain(params, w_hat, R_sw):
    """The broadcaster (X1) and the gravity filter (X2) on raw readings ``w_hat`` (fmscal's order), ``R_sw`` the
    world's axes in the sensor's (tf). Returns the filtered wrench, fmscal's order."""
    offset = np.array([params["offset"][kind][axis] for kind, axis in NAMES])
    multiplier = np.array([params["multiplier"][kind][axis] for kind, axis in NAMES])
    raw = (w_hat + offset) * multiplier                         # apply_sensor_offset, then apply_sensor_multiplier
    tool = params["sensor_filter_chain"]["filter1"]["params"]["tool"]
    weight = np.einsum("nij,j->ni", R_sw, np.array(tool["gravity_field"]) * tool["mass"])     # cst_ext_force_
    force = raw[:, 3:] - weight
    torque = raw[:, :3] - np.cross(np.array(tool["CoG"]), weight)
    return np.hstack([torque, force])


def _readings(R_tracked, mounting, sigma, gains, contact, S=None):
    """Raw readings of the tool held at the attitudes (tracked frame in the world), with a contact wrench: the mount
    and the environment hold the tool, ``w_s + w_e = W_p`` (C1), read as ``w_s = diag(gains) S (sigma w_hat - b)``."""
    R_s = R_tracked @ mounting                                   # the sensor's axes in the world
    g_s = np.einsum("nji,j->ni", R_s, G)                         # gravity in the sensor's axes
    force = -TOOL.mass * g_s                                     # what holds the tool up
    W_p = np.hstack([np.cross(COM, force), force])
    w_s = W_p - contact
    S = np.eye(6) if S is None else S
    r = np.linalg.solve(np.diag(gains) @ S, w_s.T).T
    return sigma * (r + OFFSET), np.transpose(R_s, (0, 2, 1)), w_s


@pytest.mark.parametrize("reading, sigma", [("reaction", 1.0), ("load", -1.0)])
@pytest.mark.parametrize("gains", [None, GAINS])
def test_the_chain_gives_the_contact_wrench_for_either_sign(reading, sigma, gains):
    params = _read_back(ros2_control_parameters(_estimate(reading, gains), "ft_sensor", "base_link"))
    R = _attitudes(12, seed=1)
    contact = np.random.default_rng(2).normal(size=(12, 6)) * [0.3, 0.3, 0.3, 5.0, 5.0, 5.0]
    contact[:4] = 0.0                                            # four poses with no contact
    w_hat, R_sw, _ = _readings(R, MOUNT, sigma, np.ones(6) if gains is None else gains, contact)
    out = chain(params, w_hat, R_sw)
    np.testing.assert_allclose(out, contact, rtol=0, atol=1e-9)
    assert np.abs(out[:4]).max() < 1e-9
    # the signs as the issue states them: offset -sigma b, multiplier -sigma (times the gains)
    expected = -sigma * (np.ones(6) if gains is None else gains)
    assert [params["multiplier"][k][a] for k, a in NAMES] == pytest.approx(expected, rel=1e-15)
    assert [params["offset"][k][a] for k, a in NAMES] == pytest.approx(-sigma * OFFSET, rel=1e-15)


def test_the_wrong_sign_would_show():
    """The check can fail: a reaction sensor exported as a load one leaves twice the weight (and the offset)."""
    params = _read_back(ros2_control_parameters(_estimate("load", None), "ft_sensor", "base_link"))
    w_hat, R_sw, _ = _readings(_attitudes(6, seed=3), MOUNT, 1.0, np.ones(6), np.zeros((6, 6)))
    out = chain(params, w_hat, R_sw)
    assert np.all(np.abs(np.linalg.norm(out[:, 3:], axis=1) / (2 * TOOL.mass * 9.81) - 1) < 0.1)


def test_a_tables_fit_from_its_file_compensates_fresh_poses(tmp_path):
    """End to end: held poses of a load sensor askew on a tilted base, fitted with gravity and the mounting
    estimated, saved, exported from the file; at new attitudes the chain leaves the contact to the fit's error."""
    table = simulate_table(TOOL, n=16, seed=5, gravity=G, offset=OFFSET, mounting=MOUNT, reading="load")
    fit = fit_static(table, estimate_gravity=True, estimate_mounting=True, reading="load")
    fit.save(tmp_path / "tool.json")
    exported = ros2_control_parameters(tmp_path / "tool.json", "ft_sensor", "base_link")
    exported.save(tmp_path / "params.yaml")
    params = yaml.safe_load((tmp_path / "params.yaml").read_text())["force_torque_sensor_broadcaster"][
        "ros__parameters"]
    R = _attitudes(40, seed=6)
    contact = np.zeros((40, 6))
    contact[20:] = [0.2, -0.1, 0.05, 3.0, -2.0, 4.0]
    w_hat, R_sw, _ = _readings(R, MOUNT, -1.0, np.ones(6), contact)
    error = chain(params, w_hat, R_sw) - contact
    # the fit's errors: mass 1 g, the offset 0.01 N and 1e-3 N m, the rotations 0.05 degrees of 11.8 N
    assert np.abs(error[:, 3:]).max() < 0.1 and np.abs(error[:, :3]).max() < 0.01, np.abs(error).max(axis=0)


def test_the_crosstalk_left_out_is_stated_as_it_is():
    """With a calibration, the multipliers take S's diagonal; what its off-diagonal leaves of the weight (X5) is the
    chain's largest error over attitudes."""
    rng = np.random.default_rng(7)
    S = np.eye(6) + 0.02 * rng.normal(size=(6, 6))
    calibration = Calibration(S=S, payload=TOOL, method="given", reading="reaction")
    exported = ros2_control_parameters(_estimate("reaction", None), "ft_sensor", "base_link", calibration=calibration)
    params = _read_back(exported)
    assert [params["multiplier"][k][a] for k, a in NAMES] == pytest.approx(-np.diag(S), rel=1e-15)
    w_hat, R_sw, _ = _readings(_attitudes(4000, seed=8), MOUNT, 1.0, np.ones(6), np.zeros((4000, 6)), S=S)
    worst = np.abs(chain(params, w_hat, R_sw)).max(axis=0)
    assert np.all(worst <= exported.crosstalk * (1 + 1e-9)) and np.all(worst > 0.97 * exported.crosstalk), (
        worst / exported.crosstalk)
    assert any("off-diagonal" in note for note in exported.notes)


# --- the definitions of Jazzy's and Kilted's releases ---------------------------------------------------------------

def definitions(path):
    """The parameters of a generate_parameter_library file: ``{dotted name: its spec}`` (its namespace key left)."""
    (_, tree), = yaml.safe_load(path.read_text()).items()
    found = {}

    def walk(node, prefix):
        for key, value in node.items():
            if isinstance(value, dict) and "type" in value:
                found[prefix + key] = value
            elif isinstance(value, dict):
                walk(value, prefix + key + ".")
    walk(tree, "")
    return found


def leaves(mapping, prefix=""):
    """``{dotted name: value}`` of a nested parameter mapping (lists are values)."""
    out = {}
    for key, value in mapping.items():
        if isinstance(value, dict):
            out.update(leaves(value, f"{prefix}{key}."))
        else:
            out[prefix + key] = value
    return out


def check_type(name, value, spec):
    """``value`` as generate_parameter_library's ``spec`` types and validates it."""
    kind = spec["type"]
    if kind == "string":
        assert isinstance(value, str), name
    elif kind == "double":
        assert type(value) is float, name                     # an integer would be refused by rclcpp as a double
    elif kind == "double_array":
        assert isinstance(value, list) and all(type(v) is float for v in value), name
    else:
        pytest.fail(f"{name}: the export writes a {kind} parameter; check_type does not know it")
    validation = spec.get("validation") or {}
    if "fixed_size<>" in validation:
        assert len(value) == validation["fixed_size<>"], name
    if "not_empty<>" in validation:
        assert len(value) > 0, name


@pytest.mark.parametrize("release", RELEASES)
def test_every_name_type_and_the_nesting_match_the_releases_definitions(release):
    assert release in ROS2_CONTROL_RELEASES
    folder = DATA / release
    broadcaster = definitions(folder / "force_torque_sensor_broadcaster_parameters.yaml")
    gravity = definitions(folder / "gravity_compensation_filter_parameters.yaml")
    params = _read_back(ros2_control_parameters(_estimate("reaction", GAINS), "ft_sensor", "base_link",
                                                sensor_name="ft"))
    written = leaves(params)
    own = {k: v for k, v in written.items() if not k.startswith("sensor_filter_chain.")}
    assert {f"{kind}.{k}.{a}" for kind in ("offset", "multiplier") for k, a in NAMES} <= set(own)
    for name, value in own.items():
        assert name in broadcaster, f"{name} is not a parameter of the broadcaster ({release})"
        check_type(name, value, broadcaster[name])
    # the chain: a map of filterN, each with a name and a type (the release's own example), the filter's
    # parameters under params (filters' FilterChain: the prefix sensor_filter_chain.filterN.params)
    assert broadcaster["sensor_filter_chain"]["type"] == "none"
    example = yaml.safe_load((folder / "force_torque_sensor_broadcaster_params.yaml").read_text())
    shown = example["test_force_torque_sensor_broadcaster_with_chain"]["ros__parameters"]["sensor_filter_chain"]
    chain_ = params["sensor_filter_chain"]
    assert all(re.fullmatch(r"filter[1-9][0-9]*", key) for key in list(shown) + list(chain_))
    for key, entry in chain_.items():
        assert set(entry) == set(shown["filter1"]) | {"params"}
        assert all(isinstance(entry[k], str) for k in shown["filter1"])
    entry = chain_["filter1"]
    assert entry["type"] == GRAVITY_FILTER
    # the plugin's name is the gravity filter of wrenches in the release's plugin list
    plugins = {c.get("name"): c.get("type") for c in ElementTree.parse(folder / "control_filters.xml").iter("class")}
    assert plugins[GRAVITY_FILTER] == "control_filters::GravityCompensation<geometry_msgs::msg::WrenchStamped>"
    filter_params = leaves(entry["params"])
    assert set(filter_params) == set(gravity), set(filter_params) ^ set(gravity)     # every one, and no other
    for name, value in filter_params.items():
        check_type(name, value, gravity[name])
    assert {name for name, spec in gravity.items() if spec.get("read_only")} == set(READ_ONLY)


def test_the_vendored_definitions_name_their_release_and_commit():
    for release in RELEASES:
        readme = (DATA / release / "README.md").read_text()
        control_toolbox, ros2_controllers = (v.split()[1] for v in ROS2_CONTROL_RELEASES[release])
        assert f"| {control_toolbox} (branch `{release}`) |" in readme
        assert f"| {ros2_controllers} (branch `{release}`) |" in readme
        assert len(re.findall(r"\b[0-9a-f]{40}\b", readme)) == 4


def test_every_double_is_written_as_a_float():
    """A double written ``-1`` reads as an integer (rclcpp refuses it for a double), ``1e-05`` as a string
    (YAML 1.1): every number has a point."""
    estimate = _estimate("reaction", None)
    estimate.b = np.array([1e-5, -1e-20, 0.0, 3.0, 2e20, -1.0])
    text = ros2_control_parameters(estimate, "ft_sensor", "base_link").to_yaml()
    numbers = re.findall(r"(?<![\w.\"])-?\d[\d.e+-]*", "\n".join(line for line in text.splitlines()
                                                                  if not line.startswith("#")))
    assert numbers and all("." in n for n in numbers), numbers
    params = yaml.safe_load(text)["force_torque_sensor_broadcaster"]["ros__parameters"]
    assert all(type(v) is float for v in leaves(params["offset"]).values())
    assert params["offset"]["torque"]["x"] == -1e-5 and params["offset"]["force"]["y"] == -2e20     # -b


# --- the dynamics left out ------------------------------------------------------------------------------------------

def test_the_dynamics_left_out_are_newton_euler_beyond_the_weight():
    """(X6) from the regressor with gravity zero agrees with the plant's inverse dynamics (sensor_wrench) less the
    weight's wrench, at the sensor's attitude R M, for a payload with its inertia, the mounting turned."""
    log = SPATIAL_SCENARIOS["spatial-arm"].with_(duration=2.0).generate(seed=0)[0]
    inertia_s = np.array(TOOL.inertia)
    tensor = MOUNT @ TOOL.I_c @ MOUNT.T                                                 # the tracked frame's axes
    estimate = PayloadEstimate(mass=TOOL.mass, mass_std=1e-3, com=MOUNT @ COM, com_std=np.zeros(3),
                               inertia=np.array([tensor[0, 0], tensor[1, 1], tensor[2, 2], tensor[0, 1],
                                                 tensor[0, 2], tensor[1, 2]]),
                               inertia_std=np.zeros(6), b=OFFSET, b_std=np.zeros(6), residual_rms=None,
                               payload_determined=True, mounting=MOUNT, axes="tracked")
    found = dynamics_left_out(estimate, log, 0.2)
    q, omega, alpha, p_ddot = spatial_motion(log, 0.2)
    keep = slice(edge(log, 0.2), len(log.t) - edge(log, 0.2))
    payload = SpatialPayload(TOOL.mass, inertia_s, COM)
    q_m = np.r_[np.cos(np.radians(3.0)), np.sin(np.radians(3.0)) * np.array([0.3, 1.0, 0.5])
                / np.linalg.norm([0.3, 1.0, 0.5])]                                   # MOUNT's quaternion
    np.testing.assert_allclose(rotation_matrices(q_m[None])[0], MOUNT, atol=1e-12)
    wrenches = []
    for k in range(len(log.t))[keep]:
        q_s = quaternion_multiply(q[k], q_m)
        moving = sensor_wrench(q_s, MOUNT.T @ omega[k], MOUNT.T @ alpha[k], p_ddot[k], payload)
        wrenches.append(np.asarray(moving) - np.asarray(sensor_wrench(q_s, np.zeros(3), np.zeros(3), np.zeros(3),
                                                                      payload)))
    wrenches = np.array(wrenches)
    force, torque = np.linalg.norm(wrenches[:, 3:], axis=1), np.linalg.norm(wrenches[:, :3], axis=1)
    assert found.inertia_counted and found.samples == len(force)
    np.testing.assert_allclose([found.force_rms, found.force_max, found.torque_rms, found.torque_max],
                               [np.sqrt(np.mean(force ** 2)), force.max(), np.sqrt(np.mean(torque ** 2)),
                                torque.max()], rtol=1e-9)
    assert 0.1 < found.force_rms < 10                          # the arm's motion: about a newton
    # without the inertia, the torque leaves out I alpha + omega x I omega, and says so
    without = dynamics_left_out(PayloadEstimate(**{**estimate.__dict__, "inertia": None, "inertia_std": None}), log)
    assert not without.inertia_counted and without.force_rms == pytest.approx(found.force_rms, rel=1e-12)
    assert without.torque_rms != pytest.approx(found.torque_rms, rel=1e-3)


# --- refusals and the command line ----------------------------------------------------------------------------------

@pytest.mark.parametrize("kwargs, message", [
    ({"sensor_frame": ""}, "sensor_frame must be a tf frame's name"),
    ({"world_frame": "/base_link"}, "world_frame must be a tf frame's name"),
    ({"controller": "ft broadcaster"}, "controller must be a ROS 2 node's name"),
    ({"calibration": Calibration(S=np.eye(6), payload=TOOL, method="given", reading="load")},
     "the calibration reads the load, the payload the reaction"),
])
def test_bad_input_is_one_line(kwargs, message):
    args = {"sensor_frame": "ft_sensor", "world_frame": "base_link", **kwargs}
    with pytest.raises(ExportError, match=message):
        ros2_control_parameters(_estimate("reaction", None), **args)


def test_a_first_format_file_and_a_table_as_log_are_refused():
    with pytest.raises(ExportError, match="no offset, sign or mounting \\(a file of format /1\\)"):
        ros2_control_parameters(Path(__file__).parent / "data" / "payload-v1" / "log-v1.json", "ft", "base")
    table = simulate_table(TOOL, n=8, seed=0)
    with pytest.raises(ExportError, match="the dynamics need a log of poses with their positions"):
        dynamics_left_out(_estimate("reaction", None), table)


def test_the_command_writes_what_the_library_returns(tmp_path, capsys):
    table = simulate_table(TOOL, n=12, seed=0, offset=OFFSET)
    fit_static(table).save(tmp_path / "tool.json")
    out = tmp_path / "params.yaml"
    args = ["export", "ros2-control", str(tmp_path / "tool.json"), "--sensor-frame", "ft_sensor", "--world-frame",
            "base_link", "--controller", "ft_broadcaster", "--out", str(out)]
    assert main(args) == 0
    printed = capsys.readouterr().out
    library = ros2_control_parameters(tmp_path / "tool.json", "ft_sensor", "base_link", controller="ft_broadcaster")
    assert out.read_text() == library.to_yaml()
    assert all(f"note: {note}" in printed for note in library.notes) and "wrote" in printed
    assert main(args) == 2 and "exists; add --overwrite" in capsys.readouterr().err
    assert main(args[:-2]) == 0 and capsys.readouterr().out == library.to_yaml()      # no --out: printed
    for bad, message in ((["export", "ros2-control", str(tmp_path / "none.json"), "--sensor-frame", "a",
                           "--world-frame", "b"], "no such file"),
                         (args[:-1] + [str(tmp_path / "p.txt")], "--out must end in .yaml")):
        assert main(bad) == 2
        err = capsys.readouterr().err
        assert message in err and len(err.strip().splitlines()) == 1, err
    json.loads((tmp_path / "tool.json").read_text())            # the payload file is untouched
