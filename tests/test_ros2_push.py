"""An exported payload pushed to a running broadcaster (fmscal.analysis.ros2.push_parameters, ``fmscal export
ros2-control --push``): a stand-in rclpy node in another process (tests/ros2_standin.py) declares Kilted's
broadcaster and gravity filter parameters, typed and read-only as their definition files say; the push sets the
run-time ones and reads back as the export wrote them; the refusals are one line.
"""

import os
import subprocess
import sys
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import pytest

from fmscal.analysis import ros2_control_parameters
from fmscal.analysis.cli import main
from fmscal.analysis.ros2 import Ros2Error, push_parameters
from fmscal.observers.payload import fit_static
from fmscal.plant.io import simulate_table
from fmscal.plant.scenarios import TOOL
import rclpy
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import parameter_value_to_python
from rcl_interfaces.srv import GetParameters
from ros2_rig import domain_id, stop

HERE = Path(__file__).resolve().parent


@contextmanager
def standin(domain, *args):
    """tests/ros2_standin.py in a subprocess of ``domain``, ready (its services up); stopped on leaving."""
    env = dict(os.environ, ROS_DOMAIN_ID=str(domain), ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST",
               PYTHONUNBUFFERED="1")
    proc = subprocess.Popen([sys.executable, str(HERE / "ros2_standin.py"), *args], env=env, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    try:
        line = proc.stdout.readline()
        if line.strip() != "ready":
            proc.wait(timeout=10)
            raise AssertionError(f"the stand-in did not start: {line!r} {proc.stderr.read()[-2000:]}")
        yield proc
    finally:
        stop(proc)


def read_back(domain, names, node="/force_torque_sensor_broadcaster"):
    """The stand-in's values of ``names``, over GetParameters."""
    context = Context()
    rclpy.init(context=context, domain_id=domain)
    reader = rclpy.create_node("fmscal_test_reader", context=context)
    try:
        client = reader.create_client(GetParameters, f"{node}/get_parameters")
        assert client.wait_for_service(timeout_sec=10)
        future = client.call_async(GetParameters.Request(names=list(names)))
        executor = SingleThreadedExecutor(context=context)
        executor.add_node(reader)
        executor.spin_until_future_complete(future, timeout_sec=10)
        return dict(zip(names, (parameter_value_to_python(v) for v in future.result().values)))
    finally:
        reader.destroy_node()
        rclpy.try_shutdown(context=context)


@pytest.fixture(scope="module")
def exported():
    return ros2_control_parameters(fit_static(simulate_table(TOOL, n=12, seed=0)), "ft_sensor", "base_link")


@pytest.mark.slow
@pytest.mark.jazzy
def test_the_run_time_parameters_are_set_and_read_back(request, exported):
    """The push sets every run-time parameter (tool.*, offset.*, multiplier.*: 15) and nothing else; the stand-in
    then holds the export's values exactly, its frames unchanged."""
    domain = domain_id(request.node.name)
    with standin(domain):
        pushed = push_parameters(exported, domain_id=domain, timeout=10)
        back = read_back(domain, list(pushed) + ["sensor_filter_chain.filter1.params.sensor_frame", "frame_id"])
    _, runtime = exported.runtime()
    assert list(pushed) == list(runtime) and len(pushed) == 15
    assert all(name.startswith(("offset.", "multiplier.", "sensor_filter_chain.filter1.params.tool."))
               for name in pushed)
    for name, value in runtime.items():
        np.testing.assert_array_equal(back[name], value, err_msg=name)
    assert back["sensor_filter_chain.filter1.params.sensor_frame"] == "ft_sensor" and back["frame_id"] == "ft_sensor"


@pytest.mark.slow
@pytest.mark.jazzy
def test_refusals_are_one_line(request, exported):
    """No such node: named, within the timeout; a chain without the gravity filter: the node's reason, none set;
    a wildcard name refused before any ROS call."""
    domain = domain_id(request.node.name)
    with pytest.raises(Ros2Error, match=r"^no node /nobody answers set_parameters_atomically within 1 s: "):
        push_parameters(exported, node="/nobody", timeout=1, domain_id=domain)
    with standin(domain, "--no-filter"):
        with pytest.raises(Ros2Error) as err:
            push_parameters(exported, domain_id=domain, timeout=10)
        back = read_back(domain, ["offset.force.x"])
    message = str(err.value)
    assert message.startswith("/force_torque_sensor_broadcaster refused the parameters, none set: ") and \
        "\n" not in message, message
    assert back["offset.force.x"] == 0.0                         # atomically: the declared ones untouched too
    with pytest.raises(Ros2Error, match=r"^the broadcaster's node must be a name such as"):
        push_parameters(exported, node="/**/broadcaster")


@pytest.mark.slow
def test_the_command_pushes(request, tmp_path, capsys, monkeypatch):
    """``fmscal export ros2-control ... --push`` (the domain ROS_DOMAIN_ID's): the file written, then the
    parameters set, a line saying so; no node: a one-line error and exit 2."""
    domain = domain_id(request.node.name)
    monkeypatch.setenv("ROS_DOMAIN_ID", str(domain))
    fit = fit_static(simulate_table(TOOL, n=12, seed=0))
    fit.save(tmp_path / "tool.json")
    args = ["export", "ros2-control", str(tmp_path / "tool.json"), "--sensor-frame", "ft_sensor", "--world-frame",
            "base_link", "--push", "--push-timeout", "10"]
    with standin(domain):
        assert main(args + ["--out", str(tmp_path / "params.yaml")]) == 0
        back = read_back(domain, ["sensor_filter_chain.filter1.params.tool.mass"])
    out = capsys.readouterr().out
    assert "pushed 15 parameters to /force_torque_sensor_broadcaster: tool.mass " in out, out
    assert back["sensor_filter_chain.filter1.params.tool.mass"] == pytest.approx(fit.mass, rel=1e-12)
    assert (tmp_path / "params.yaml").exists()
    assert main(args[:-1] + ["1"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "no node /force_torque_sensor_broadcaster answers" in err, err


@pytest.mark.slow
def test_the_node_pushes_its_payload(request, tmp_path):
    """The node from a payload file alone with push_controller: ``~/push`` sets the stand-in's run-time parameters
    to the payload in use (the file's, as its export gives them); push_controller with a calibration is refused
    at start, and ``~/push`` without it refuses in one line."""
    from ros2_rig import Peer, running_node, tool_calibration, tool_payload
    from fmscal.observers.payload import PayloadEstimate
    domain = domain_id(request.node.name)
    path = tool_payload(tmp_path / "tool.json")
    _, expected = ros2_control_parameters(PayloadEstimate.load(path), "ft_sensor", "world").runtime()
    base = (f"payload:={path}", "pose_topic:=/ft_sensor/pose", "qos:=reliable")
    with standin(domain), running_node(domain, *base, "push_controller:=/force_torque_sensor_broadcaster") as proc:
        peer = Peer(domain)
        try:
            peer.wait_for_node(proc)
            ok, message = peer.call("push")
        finally:
            peer.close()
        back = read_back(domain, list(expected))
    assert ok and message.startswith("pushed 15 parameters to /force_torque_sensor_broadcaster: tool.mass "), message
    for name, value in expected.items():                  # the file's payload and offset: nothing identified yet
        np.testing.assert_allclose(back[name], value, rtol=1e-12, atol=1e-15, err_msg=name)
    with running_node(domain, *base) as proc:
        peer = Peer(domain)
        try:
            peer.wait_for_node(proc)
            refused = peer.call("push")
        finally:
            peer.close()
    assert refused == (False, "push refused: set the parameter push_controller (with a payload file alone)")
    from fmscal.analysis.ros2 import PARAMETERS, settings
    values = {p.name: p.default for p in PARAMETERS}
    values.update(calibration=str(tool_calibration(tmp_path / "cal.json")), payload=str(path), pose_topic="/p",
                  push_controller="/force_torque_sensor_broadcaster")
    with pytest.raises(Ros2Error, match="^parameter push_controller pushes a payload file's payload"):
        settings(values)
    values.update(calibration="", push_controller="/ns/force_torque_sensor_broadcaster")
    assert settings(values).push_controller == "/ns/force_torque_sensor_broadcaster"
    for bad in ("*", "/ns/*_broadcaster", "force torque"):           # checked at start, not at the first push
        with pytest.raises(Ros2Error, match=r"^parameter push_controller must be a node's name .*got"):
            settings(dict(values, push_controller=bad))
