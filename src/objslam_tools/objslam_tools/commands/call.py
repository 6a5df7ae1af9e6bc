"""``objslam call build-map``: call the mapper's BuildMap service and print the response."""

from __future__ import annotations

import argparse
import sys
import threading
import time
from typing import Any

import yaml

from objslam_tools.ros_util import message_to_plain, ros_node

SERVICE = "/objslam/build_map"
NO_SERVICE_EXIT = 1
GONE_GRACE_S = 2.0


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser("call", help="call an objslam service (build-map)")
    calls = parser.add_subparsers(dest="service", metavar="SERVICE")
    calls.required = True
    build = calls.add_parser("build-map", help=f"build the map from what the mapper buffered ({SERVICE})")
    build.add_argument("--samples", type=int, default=0, help="MCMC samples incl. burn-in (0: mapper's default)")
    build.add_argument("--burn-in", type=int, default=0, help="samples discarded first (0: mapper's default)")
    build.add_argument("--seed", type=int, default=0, help="random seed (0: mapper's default)")
    build.add_argument("--chains", type=int, default=0, help="chains from dispersed starts (0: mapper's default)")
    build.add_argument("--wait", type=float, default=10.0, metavar="S", help="how long to wait for the service")
    build.add_argument(
        "--timeout", type=float, default=3600.0, metavar="S", help="give up on the answer after S s (default 3600)"
    )
    build.set_defaults(func=run_build_map)


def run_build_map(args: argparse.Namespace) -> int:
    import rclpy
    from rclpy.event_handler import SubscriptionEventCallbacks

    from objslam_common.ros import liveliness
    from objslam_msgs.msg import BuildProgress
    from objslam_msgs.srv import BuildMap

    for name, value in (
        ("--samples", args.samples),
        ("--burn-in", args.burn_in),
        ("--seed", args.seed),
        ("--chains", args.chains),
    ):
        if value < 0:
            print(f"objslam call: error: {name} must be >= 0", file=sys.stderr)
            return 2
    with ros_node("objslam_call") as node:
        client = node.create_client(BuildMap, SERVICE)
        # The mapper's liveliness on its progress topic: lost within seconds of its death.
        lost = threading.Event()

        def on_liveliness(event: Any) -> None:
            if event.alive_count_change < 0 and event.alive_count == 0:
                lost.set()

        node.create_subscription(
            BuildProgress,
            liveliness.PROGRESS_TOPIC,
            lambda _msg: None,
            liveliness.watched(),
            event_callbacks=SubscriptionEventCallbacks(liveliness=on_liveliness),
        )
        if not client.wait_for_service(timeout_sec=args.wait):
            print(
                f"objslam call: no service answered at {SERVICE} within {args.wait:g} s (is the mapper running?)",
                file=sys.stderr,
            )
            return NO_SERVICE_EXIT
        request = BuildMap.Request(samples=args.samples, burn_in=args.burn_in, seed=args.seed, chains=args.chains)
        started = time.monotonic()
        future = client.call_async(request)
        gone_since = None
        while rclpy.ok() and not future.done():
            if time.monotonic() - started > args.timeout:
                print(
                    f"objslam call: no answer within {args.timeout:g} s (the build may still run: "
                    "watch /objslam/map/progress, or give a longer --timeout)",
                    file=sys.stderr,
                )
                return NO_SERVICE_EXIT
            rclpy.spin_once(node, timeout_sec=0.1)
            # A mapper that died mid-build never answers: notice that its liveliness lapsed
            # or, where the middleware reports none, that its service went away (after a
            # grace period, as discovery may flicker; DDS notices that only after its lease).
            if client.service_is_ready():
                gone_since = None
            elif gone_since is None:
                gone_since = time.monotonic()
            if lost.is_set() or (gone_since is not None and time.monotonic() - gone_since > GONE_GRACE_S):
                print(
                    "objslam call: the mapper went away during the build (see its log, start it again and call again)",
                    file=sys.stderr,
                )
                return NO_SERVICE_EXIT
        response = future.result()
    # A response is a few fields, and its message says what went wrong: print it whole.
    sys.stdout.write(yaml.safe_dump(message_to_plain(response, truncate_length=None), sort_keys=False))
    return 0 if response.success else 1
