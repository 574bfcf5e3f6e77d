"""``scattertrack`` run in-process for the command-line tests, and what it printed."""

from scattertrack.cli import main


def run(capsys, *argv) -> tuple[int, str, str]:
    """main(argv) with its exit code, stdout and stderr."""
    code = main([str(a) for a in argv])
    captured = capsys.readouterr()
    return code, captured.out, captured.err


def assert_rejected(code: int, out: str, err: str, *fragments: str) -> None:
    """Exit 2, no traceback, and the last stderr line is the error with every fragment."""
    assert code == 2, (out, err)
    assert "Traceback" not in out + err
    last = err.rstrip("\n").split("\n")[-1]
    assert last.startswith("scattertrack: error: "), err
    for fragment in fragments:
        assert fragment in last, (fragment, last)


def warning_lines(text: str) -> list[str]:
    """The ``warning:`` lines of what a command printed."""
    return [line for line in text.splitlines() if line.startswith("warning: ")]


def with_cell(rows: list[str], row: int, column: int, value: str) -> list[str]:
    """CSV lines ``rows`` with cell ``column`` of line ``row`` replaced by ``value``."""
    cells = rows[row].split(",")
    cells[column] = value
    return [*rows[:row], ",".join(cells), *rows[row + 1:]]
