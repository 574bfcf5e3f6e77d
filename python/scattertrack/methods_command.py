"""``scattertrack scenarios`` and ``scattertrack methods``: what can be simulated and tracked.

    scattertrack scenarios
    scattertrack methods [--params METHOD] [--markdown]
"""

from __future__ import annotations

import sys

from scattertrack.arguments import say


def add_parsers(commands) -> None:
    scenarios = commands.add_parser("scenarios", help="list the named simulation scenarios and their pipeline")
    scenarios.set_defaults(run=command_scenarios)

    methods = commands.add_parser(
        "methods",
        help="list the tracking methods, or one method's parameters",
        description="One line per method: its name, what it does and its input. With --params METHOD: "
        "that method's parameters (name, type, default, range, unit, description), as docs/parameters.md.",
    )
    methods.add_argument("--params", metavar="METHOD", help="print this method's parameter table")
    methods.add_argument("--markdown", action="store_true", help="print every table as Markdown (docs/parameters.md)")
    methods.set_defaults(run=command_methods)


def command_scenarios(args) -> int:
    from scattertrack import FormatError, sim

    names = sim.list_scenarios("all")
    if not names:
        say(f"no scenarios in {sim.SCENARIOS_DIR}")
        return 0
    width = max(len(name) for name in names)
    pipeline_width = max(len(p) for p in sim.PIPELINES)
    for name in names:
        pipeline = sim.scenario_pipeline(name)
        try:
            description = sim.load_scenario(name).get("description", "")
        except FormatError as error:
            # One broken file must not hide the others.
            description = f"(invalid: {error})"
        say(f"{name.ljust(width)}  {pipeline.ljust(pipeline_width)}  {description}")
    return 0


def command_methods(args) -> int:
    """One line per method (name, description, input); ``--params NAME``: that method's table."""
    from scattertrack.track import methods, parameters

    if args.markdown:
        sys.stdout.write(parameters.markdown())
        return 0
    if args.params:
        methods.method(args.params)  # an unknown name is an error naming the known ones
        for line in parameters.plain_table(args.params):
            say(line)
        return 0
    width = max(len(name) for name in methods.METHODS)
    for m in methods.REGISTRY.values():
        say(f"{m.name.ljust(width)}  {m.description} (input: {m.input_files})")
    return 0
