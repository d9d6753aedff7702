"""ROS 2 launch file for the sepmem node.

sepmem is not an rclcpp/rclpy node: it speaks rmw_zenoh's wire protocol
directly (or runs through r2r when built with `--features ros2`). This launch
file starts the `sepmem node` executable as a plain process with its
parameters mapped to `--set node.<key>=<value>` overrides, so it fits in a
ROS 2 launch tree next to rmw_zenoh nodes.

    ros2 launch launch/sepmem.launch.py topics:='["/seg/**"]' connect:=tcp/127.0.0.1:7447

Arguments (defaults are those of launch/sepmem.json5):
  sepmem        path of the sepmem executable (default: `sepmem` on PATH)
  config        a JSON5/TOML file with the keys to change ('' = none)
  topics        JSON list of input topic patterns
  key_mode      ros2 | bridge | plain
  domain_id     ROS domain id ('' = $ROS_DOMAIN_ID)
  connect       zenoh endpoint of the router (rmw_zenohd), '' = none
  listen        zenoh endpoint to listen on, '' = zenoh default
  node_name     ROS node name
  shard_index   this instance's shard index
  shard_count   number of instances sharing the streams
  deadline_ms   warm-frame deadline in ms from receipt (pipeline.deadline_ms)
  cold_deadline_ms  deadline of a stream's cold frames (pipeline.cold_deadline_ms)
  log           tracing filter (e.g. info, sepmem=debug)
"""

from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, OpaqueFunction, ExecuteProcess
from launch.substitutions import LaunchConfiguration

ARGS = {
    "sepmem": "sepmem",
    "config": "",
    "topics": "",
    "key_mode": "",
    "domain_id": "",
    "connect": "",
    "listen": "",
    "node_name": "",
    "shard_index": "",
    "shard_count": "",
    "deadline_ms": "",
    "cold_deadline_ms": "",
    "log": "info",
}

# launch argument -> sepmem config key
KEYS = {
    "topics": "node.topics",
    "key_mode": "node.transport.key_mode",
    "domain_id": "node.transport.domain_id",
    "node_name": "node.transport.node_name",
    "shard_index": "node.shard.index",
    "shard_count": "node.shard.count",
    "deadline_ms": "pipeline.deadline_ms",
    "cold_deadline_ms": "pipeline.cold_deadline_ms",
}


def _command(context):
    get = lambda name: LaunchConfiguration(name).perform(context)
    cmd = [get("sepmem"), "--log", get("log"), "node"]
    if get("config"):
        cmd += ["--config", get("config")]
    for arg, key in KEYS.items():
        if get(arg):
            cmd += ["--set", f"{key}={get(arg)}"]
    if get("connect"):
        cmd += ["--set", f'node.transport.zenoh.connect=["{get("connect")}"]']
    if get("listen"):
        cmd += ["--set", f'node.transport.zenoh.listen=["{get("listen")}"]']
    # SIGINT on shutdown: the node publishes final diagnostics and withdraws
    # its liveliness tokens within node.shutdown_timeout_ms.
    return [ExecuteProcess(cmd=cmd, output="screen", sigterm_timeout="5")]


def generate_launch_description():
    return LaunchDescription(
        [DeclareLaunchArgument(name, default_value=value) for name, value in ARGS.items()]
        + [OpaqueFunction(function=_command)]
    )
