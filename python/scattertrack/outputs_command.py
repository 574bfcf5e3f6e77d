"""The robot outputs' options, shared by ``live`` and ``stream``.

    [--mcap FILE] [--ros2-bag DIR]            (live: ROS 2 files written as it goes)
    [--frame-id F] [--transform x,y,z,qw,qx,qy,qz]
    [--foxglove [HOST:]PORT] [--mqtt-out HOST[:PORT]]

The outputs themselves are :mod:`scattertrack.readers.outputs`; this
module only parses the options, starts them and says where they went.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from scattertrack.arguments import ascii_int, plural, say

MQTT_PORT = 1883
"""The IANA port of MQTT (8883 with TLS)."""


def mqtt_address(text: str) -> tuple[str, int]:
    """``HOST[:PORT]`` of an MQTT broker (port 1883 by default)."""
    from scattertrack.arguments import host_and_port

    return host_and_port(text, MQTT_PORT)


def foxglove_address(text: str) -> tuple[str, int]:
    """``[HOST:]PORT`` to serve the Foxglove WebSocket on (loopback unless a host is given; port 0: a free one)."""
    host, _, number = text.rpartition(":")
    host = host.strip("[]") if host else "127.0.0.1"
    try:
        port = ascii_int(number)
    except (ValueError, argparse.ArgumentTypeError):
        port = -1
    if not host or not 0 <= port <= 65535:
        raise argparse.ArgumentTypeError(f"expected [HOST:]PORT with a port from 0 to 65535, got {text!r}")
    return host, port


def add_output_options(parser, files: bool, live: bool = True) -> None:
    """The ROS 2 and robot outputs of ``live`` (``files``, ``live``), ``stream``
    (``live``) and ``track`` (``files`` only: written after the run)."""
    when = " as it goes" if live else ""
    if files:
        parser.add_argument("--mcap", help=f"also write the track as MCAP with ROS 2 messages{when} (pose and odometry per row, antennas)")
        parser.add_argument("--ros2-bag", help=f"also write the track as a ROS 2 bag directory (must not exist){when}, without a ROS install")
    parser.add_argument("--frame-id", default="scattertrack", help="frame_id of the ROS 2 messages (default scattertrack: the scene's frame)")
    parser.add_argument("--transform", help="scene-to-robot transform x,y,z,qw,qx,qy,qz applied to the ROS 2 messages")
    if not live:
        return
    parser.add_argument("--foxglove", type=foxglove_address, metavar="[HOST:]PORT", help="serve the ROS 2 messages live on a Foxglove WebSocket (host 127.0.0.1 unless given)")
    parser.add_argument("--mqtt-out", type=mqtt_address, metavar="HOST[:PORT]", help="publish every estimate as JSON to this MQTT broker (scattertrack/tags/<EPC>/estimate)")


def output_options(args, parquet: str | None = None):
    """:class:`~scattertrack.readers.outputs.OutputOptions` from the options above.
    A bad --transform or an existing --ros2-bag fails before anything starts."""
    from scattertrack.readers.outputs import OutputOptions

    return OutputOptions(
        parquet=parquet,
        mcap=getattr(args, "mcap", None),
        ros2_bag=getattr(args, "ros2_bag", None),
        foxglove=args.foxglove,
        mqtt=args.mqtt_out,
        frame_id=args.frame_id,
        transform=ros2_transform(args),
    )


def ros2_transform(args):
    """The ``--transform`` (identity without one). A bad one, or a
    ``--ros2-bag`` directory that exists, fails (ValueError) before anything runs."""
    from scattertrack.io import ros2

    if getattr(args, "ros2_bag", None) and Path(args.ros2_bag).exists():
        raise ValueError(f"--ros2-bag {args.ros2_bag}: already exists (a ROS 2 bag is a new directory)")
    if getattr(args, "transform", None) is None:
        return ros2.IDENTITY
    try:
        return ros2.Transform.parse(args.transform)
    except ValueError as error:
        raise ValueError(f"--transform: {error}") from None


def write_ros2_files(args, result, scene, transform) -> None:
    """``track``'s --mcap and --ros2-bag: the finished track as ROS 2 messages, one pose and one odometry per row."""
    from scattertrack.io import ros2

    if args.mcap:
        counts = ros2.write_mcap(args.mcap, result, scene, args.frame_id, transform)
        say(f"  wrote {sum(counts.values())} ROS 2 messages on {len(counts)} topics to {args.mcap}")
    if args.ros2_bag:
        counts = ros2.write_ros2_bag(args.ros2_bag, result, scene, args.frame_id, transform)
        say(f"  wrote {sum(counts.values())} ROS 2 messages on {len(counts)} topics to the bag {args.ros2_bag}")


def start_outputs(args, scene):
    """``stream``'s --foxglove and --mqtt-out, started (None: neither given)."""
    from scattertrack.readers.outputs import LiveOutputs

    options = output_options(args)
    if not options.any:
        return None
    outputs = LiveOutputs(options, scene)
    if outputs.foxglove is not None:
        say(f"  Foxglove WebSocket on ws://{options.foxglove[0]}:{outputs.foxglove.port}")
    return outputs


def finish_outputs(outputs, track) -> None:
    """Publish ``stream``'s track through ``outputs``, then close them."""
    from scattertrack.readers.outputs import publish_track

    if outputs is None:
        return
    try:
        publish_track(outputs, track)
    finally:
        outputs.close()
    say_outputs(outputs)


def say_outputs(outputs) -> None:
    """Where the outputs went (after the run)."""
    options = outputs.options
    if options.parquet:
        say(f"  wrote the track as Parquet to {options.parquet}")
    for path, kind in ((options.mcap, "MCAP file"), (options.ros2_bag, "ROS 2 bag")):
        if path:
            say(f"  wrote {plural(outputs.messages, 'ROS 2 message')} on {plural(len(outputs.topics), 'topic')} to the {kind} {path}")
    if outputs.foxglove_published is not None:
        say(f"  served {plural(outputs.foxglove_published, 'message')} on the Foxglove WebSocket {options.foxglove[0]}:{outputs.foxglove_port}")
    if outputs.mqtt_published is not None:
        say(f"  published {plural(outputs.mqtt_published, 'estimate')} to the MQTT broker {options.mqtt[0]}:{options.mqtt[1]}")
