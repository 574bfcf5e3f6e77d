"""Property test: any valid Reads written and read back is equal within the written precision."""

import math
import tempfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from scattertrack.io import Reads, read_reads, write_reads

# Tag ids: hex digits of either case (reads.csv accepts nothing else; case is kept).
EPC = st.text(alphabet="0123456789ABCDEFabcdef", min_size=1, max_size=24)
OPTIONAL_VALUE = st.one_of(st.just(math.nan), st.floats(-200.0, 200.0))


@st.composite
def reads_strategy(draw) -> Reads:
    n = draw(st.integers(1, 40))
    # Distinct whole microseconds: the written precision, so no two rows
    # become duplicates (or swap order) when written with 6 decimals.
    microseconds = draw(st.lists(st.integers(0, 10**10), min_size=n, max_size=n, unique=True))
    return Reads(
        time_s=np.array(microseconds, dtype=np.float64) / 1e6,
        epc=np.array(draw(st.lists(EPC, min_size=n, max_size=n)), dtype=str),
        antenna=np.array(draw(st.lists(st.integers(0, 2**31), min_size=n, max_size=n))),
        frequency_hz=np.array(draw(st.lists(st.floats(100e6, 10e9), min_size=n, max_size=n))),
        phase_rad=np.array(
            draw(st.lists(st.floats(0.0, 2 * math.pi, exclude_max=True), min_size=n, max_size=n))
        ),
        rssi_dbm=np.array(draw(st.lists(OPTIONAL_VALUE, min_size=n, max_size=n))),
        doppler_hz=np.array(draw(st.lists(OPTIONAL_VALUE, min_size=n, max_size=n))),
    )


@pytest.mark.filterwarnings("ignore::scattertrack.io.InputWarning")  # random times jump about
@settings(max_examples=150, deadline=None)
@given(reads_strategy())
def test_reads_round_trip(reads):
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "reads.csv"
        write_reads(path, reads)
        again = read_reads(path)
    order = np.argsort(reads.time_s, kind="stable")  # the reader sorts by time
    expected = reads.select(order)
    assert len(again) == len(expected)
    assert again.skipped.total == 0
    np.testing.assert_allclose(again.time_s, expected.time_s, rtol=0, atol=5e-7)
    np.testing.assert_array_equal(again.epc, expected.epc)
    np.testing.assert_array_equal(again.antenna, expected.antenna)
    np.testing.assert_array_equal(again.frequency_hz, expected.frequency_hz)
    np.testing.assert_allclose(again.phase_rad, expected.phase_rad, rtol=0, atol=1e-6)
    assert ((again.phase_rad >= 0) & (again.phase_rad < 2 * math.pi)).all()
    for name in ("rssi_dbm", "doppler_hz"):
        np.testing.assert_allclose(getattr(again, name), getattr(expected, name), rtol=0, atol=5e-3)
