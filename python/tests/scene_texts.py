"""scene.toml texts shared by tests: a localization helper with the transmitter
at (0.4, 0.4, 0) and up to four receivers round it (the project's cross layout),
and a reader with three antennas on the line x = 0."""

RECEIVERS = [(0.0, 0.4, 0.0), (0.8, 0.4, 0.0), (0.4, 0.0, 0.0), (0.4, 0.8, 0.0)]


def helper_scene(receivers: int = 4, tail: str = "") -> str:
    """The helper scene with the first ``receivers`` receivers (ids 1…), then ``tail`` (more TOML)."""
    lines = ['name = "helper"', "dimensions = 3", "", "[reader]", 'kind = "sdr-helper"', "", "[[antennas]]", "id = 0", "position = [0.4, 0.4, 0.0]", 'role = "tx"']
    for i, (x, y, z) in enumerate(RECEIVERS[:receivers], start=1):
        lines += ["", "[[antennas]]", f"id = {i}", f"position = [{x}, {y}, {z}]", 'role = "rx"']
    text = "\n".join(lines) + "\n"
    return text + ("\n" + tail if tail else "")


LINE = [(0.0, 0.0, 0.0), (0.0, 0.3, 0.0), (0.0, 0.8, 0.0)]
"""Three antennas on the line x = 0, z = 0 (ids 1-3)."""


def line_scene(name: str, kind: str = "cots") -> str:
    """A reader scene of ``kind`` named ``name`` with the :data:`LINE` antennas (16 lines:
    the third antenna's position is line 16)."""
    lines = [f'name = "{name}"', "dimensions = 3", "", "[reader]", f'kind = "{kind}"']
    for i, (x, y, z) in enumerate(LINE, start=1):
        lines += ["", "[[antennas]]", f"id = {i}", f"position = [{x}, {y}, {z}]"]
    return "\n".join(lines) + "\n"
