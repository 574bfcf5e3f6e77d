"""Numeric command-line options are ASCII decimal, like the files' numbers."""

import pytest

from scattertrack.cli import main


@pytest.mark.parametrize("value", ["１０", "1_0", "0x10", "ten"])
def test_a_number_option_that_is_not_ascii_decimal_exits_2(capsys, tmp_path, value):
    assert main(["simulate", "--scenario", "glac-2d-10cms", "--out", str(tmp_path), "--duration", value]) == 2
    assert "not an ASCII decimal number" in capsys.readouterr().err


def test_an_integer_option_takes_ascii_digits_only(capsys, tmp_path):
    assert main(["simulate", "--scenario", "glac-2d-10cms", "--out", str(tmp_path), "--seed", "３"]) == 2
    assert "not an ASCII integer" in capsys.readouterr().err


def test_plain_numbers_still_work(tmp_path):
    assert main(["simulate", "--scenario", "glac-2d-10cms", "--out", str(tmp_path), "--duration", "1.5e0", "--seed", "+3"]) == 0
