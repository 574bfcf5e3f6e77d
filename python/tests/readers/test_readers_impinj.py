"""What an Impinj tag report means (scattertrack.readers.impinj)."""

from __future__ import annotations

import math

import pytest
from hypothesis import given
from hypothesis import strategies as st

from scattertrack.readers import impinj

HOP = impinj.hop_table_hz([915_250, 902_750, 927_250])


def test_phase_units_are_4096_per_turn():
    assert impinj.phase_rad(0) == 0.0
    assert impinj.phase_rad(1024) == pytest.approx(math.pi / 2)
    assert impinj.phase_rad(4096) == 0.0
    assert impinj.phase_units(math.pi) == 2048
    assert impinj.phase_units(2 * math.pi - 1e-6) == 0  # rounds onto the turn, wraps


@given(st.integers(0, 4095))
def test_phase_round_trip(units):
    assert impinj.phase_units(impinj.phase_rad(units)) == units


def test_doppler_is_sixteenths_of_a_hertz_and_saturates():
    assert impinj.doppler_hz(-40) == -2.5
    assert impinj.doppler_units(2.5) == 40
    assert impinj.doppler_units(1e6) == 32767
    assert impinj.rssi_dbm(-5523) == -55.23


def test_hop_table_is_one_based_in_the_readers_order():
    assert HOP == {1: 915_250_000.0, 2: 902_750_000.0, 3: 927_250_000.0}


def _report(**overrides):
    fields = dict(epc=bytes.fromhex("E2000A01"), antenna=2, channel_index=2, first_seen_us=1_796_000_000_123_456, phase_deg=90.0, rssi=-55.5, doppler=1.25, hop_table=HOP)
    fields.update(overrides)
    return impinj.reported_read(**fields)


def test_a_report_becomes_a_read_in_si_units():
    read = _report()
    assert read.time_s == 1_796_000_000.123456
    assert read.epc == "E2000A01"
    assert (read.antenna, read.channel_index) == (2, 2)
    assert read.frequency_hz == 902_750_000.0  # channel 2 of this reader's table, not of the band plan
    assert read.phase_rad == pytest.approx(math.pi / 2)
    assert (read.rssi_dbm, read.doppler_hz) == (-55.5, 1.25)


def test_optional_fields_absent_are_nan():
    read = _report(rssi=None, doppler=None)
    assert math.isnan(read.rssi_dbm) and math.isnan(read.doppler_hz)


@pytest.mark.parametrize(
    "field, value, reason",
    [
        ("phase_deg", None, "without a phase"),
        ("channel_index", None, "without a channel index"),
        ("channel_index", 9, "channel index 9 is not in the reader's hop table"),
        ("antenna", None, "without an antenna"),
        ("first_seen_us", None, "FirstSeenTimestampUTC"),
    ],
)
def test_reports_that_cannot_be_reads_say_why(field, value, reason):
    result = _report(**{field: value})
    assert isinstance(result, str) and reason in result
