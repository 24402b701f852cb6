"""ROS parameters generated from a config dataclass: declaration, overrides, validation of run-time changes."""
from dataclasses import dataclass

import pytest
from rcl_interfaces.msg import ParameterType
from rclpy.parameter import Parameter

from lightfast.config import Config, ConfigError, param
from lightfast.nodes import NODE_CONFIGS, node_config_class
from lightfast.ros.params import ConfigParameters, declare_config, unknown_parameters
from test.conftest import ROOT


@dataclass(frozen=True)
class DemoConfig(Config):
    chunk_size: int = param(100, description="Vertices per chunk.", min=1, max=1000)
    gain: float = param(0.5, description="Gain.", min=0.0, max=1.0)
    mode: str = param("a", description="Mode.", choices=("a", "b"))
    weights: tuple[float, ...] = param((), description="Weights.")
    map_path: str = param("", description="Map.", read_only=True)


def test_declares_every_field_with_descriptor(make_node) -> None:
    node = make_node("params_demo")
    cfg = declare_config(node, DemoConfig)
    assert cfg == DemoConfig()
    desc = node.describe_parameter("chunk_size")
    assert desc.type == ParameterType.PARAMETER_INTEGER
    assert "Vertices per chunk" in desc.description
    assert (desc.integer_range[0].from_value, desc.integer_range[0].to_value) == (1, 1000)
    assert node.describe_parameter("weights").type == ParameterType.PARAMETER_DOUBLE_ARRAY
    assert node.describe_parameter("map_path").read_only


def test_overrides_are_validated(make_node) -> None:
    node = make_node("params_ok", parameter_overrides=[Parameter("gain", value=0.25),
                                                       Parameter("weights", value=[1.0, 2.0])])
    cfg = declare_config(node, DemoConfig)
    assert cfg.gain == 0.25 and cfg.weights == (1.0, 2.0)
    bad = make_node("params_bad", parameter_overrides=[Parameter("mode", value="zzz")])
    with pytest.raises(ConfigError, match=r"params_bad: invalid parameter: .*mode='zzz' is not one of"):
        declare_config(bad, DemoConfig)


def test_a_wrong_type_or_range_on_the_command_line_is_a_config_error(make_node) -> None:
    """`--ros-args -p gain:=1` gives an integer: rclpy raises its own exception, which run_node would show as a
    traceback; declare_config turns it into a ConfigError naming the parameter (one line, exit code 1)."""
    node = make_node("params_int", parameter_overrides=[Parameter("gain", value=1)])
    with pytest.raises(ConfigError, match=r"params_int: parameter gain must be of type double .*decimal point"):
        declare_config(node, DemoConfig)
    node = make_node("params_str", parameter_overrides=[Parameter("chunk_size", value="ten")])
    with pytest.raises(ConfigError, match=r"params_str: parameter chunk_size must be of type integer"):
        declare_config(node, DemoConfig)
    node = make_node("params_range", parameter_overrides=[Parameter("gain", value=2.0)])
    with pytest.raises(ConfigError, match=r"params_range: invalid parameter gain: .*out of range"):
        declare_config(node, DemoConfig)


def test_runtime_changes_are_checked_by_the_dataclass(make_node) -> None:
    node = make_node("params_live")
    seen: list[DemoConfig] = []
    params = ConfigParameters(node, DemoConfig, on_change=seen.append)
    result = node.set_parameters([Parameter("mode", value="c")])[0]
    assert not result.successful and "not one of" in result.reason
    assert params.config.mode == "a"
    assert node.set_parameters([Parameter("mode", value="b")])[0].successful
    assert params.config.mode == "b" and seen[-1].mode == "b"
    assert not node.set_parameters([Parameter("map_path", value="/x")])[0].successful  # read-only


# --- the shipped parameter files, read by rcl --------------------------------------------------------------------

def _node_from_params_file(path, node_name: str, domain_id: int):
    """A context initialised with ``--ros-args --params-file path`` (rcl parses the file) and a node named like
    the real one: what `ros2 run lightfast <node> --ros-args --params-file path` gives the node's parameters."""
    import rclpy
    from rclpy.context import Context
    from rclpy.node import Node
    from rclpy.signals import SignalHandlerOptions

    context = Context()
    rclpy.init(args=["--ros-args", "--params-file", str(path)], context=context, domain_id=domain_id,
               signal_handler_options=SignalHandlerOptions.NO)
    return context, Node(node_name, context=context)


@pytest.mark.parametrize("node_name", sorted(NODE_CONFIGS))
def test_every_shipped_parameter_file_loads_through_rcl(node_name: str, domain_id: int) -> None:
    """config/<node>.yaml through rcl's own YAML parser gives exactly the dataclass defaults (rcl read the unquoted
    ``init_axes: [x, y]`` as booleans and refused the file), and no key the node does not know."""
    import rclpy

    path = ROOT / "config" / f"{node_name}.yaml"
    cls = node_config_class(node_name)
    context, node = _node_from_params_file(path, node_name, domain_id)
    try:
        assert declare_config(node, cls) == cls()
        assert unknown_parameters(node) == {}
    finally:
        node.destroy_node()
        rclpy.try_shutdown(context=context)


def test_an_unknown_parameter_is_reported_with_the_closest_name(make_node) -> None:
    node = make_node("params_typo", parameter_overrides=[Parameter("chunk_sise", value=3),
                                                         Parameter("zzz_nothing_like_it", value=1.0)])
    declare_config(node, DemoConfig)
    assert unknown_parameters(node) == {"chunk_sise": "chunk_size", "zzz_nothing_like_it": None}
