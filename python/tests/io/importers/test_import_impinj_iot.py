"""impinj-iot: the sample, units, ISO 8601 times, every declined event kind, round trip."""

import math

import numpy as np
import pytest

from scattertrack.io import FormatError
from scattertrack.io.importers import import_impinj_iot
from scattertrack.io.importers.impinj_iot import iso_seconds

from import_helpers import assert_round_trip, run_quietly

EVENT = ('{"timestamp":"2023-11-14T22:13:20Z","eventType":"tagInventory","tagInventoryEvent":'
         '{"epcHex":"E2801170","antennaPort":1,"peakRssiCdbm":-5800,"frequency":915250,"phaseAngle":45.0%s}}')


def imported(write_file, scene, text):
    return run_quietly(lambda: import_impinj_iot([write_file("events.jsonl", text)], scene))


def test_sample_values_units_and_counts(data, scene):
    (reads, report), found = run_quietly(lambda: import_impinj_iot([data / "impinj_iot.jsonl"], scene))
    assert reads.epc.tolist() == ["E28011700000020A1B2C3D01"] * 2 + ["E28011700000020A1B2C3D02"]  # base64 decoded
    np.testing.assert_allclose(reads.time_s - 1700000000.0, [0.0, 0.01, 0.02], atol=1e-6)
    assert reads.antenna.tolist() == [1, 3, 2]
    assert reads.frequency_hz.tolist() == [902.75e6, 915.25e6, 927.25e6]  # kHz
    np.testing.assert_allclose(reads.phase_rad, [math.pi / 2, math.radians(33.75), math.pi])  # degrees
    assert reads.rssi_dbm.tolist() == [-58.0, -60.0, -61.5]  # centi-dBm
    assert np.isnan(reads.doppler_hz).all() and reads.channel_index is None
    assert (report.rows, report.kept, report.duplicates, report.reordered, report.declined_total) == (5, 3, 1, 1, 0)
    assert report.ignored == {"inventoryStatus events": 1}
    assert "ignored 1 inventoryStatus events" in report.summary()
    assert found == []


def test_sample_round_trip(data, scene, tmp_path):
    (reads, _), _ = run_quietly(lambda: import_impinj_iot([data / "impinj_iot.jsonl"], scene))
    assert_round_trip(reads, scene, tmp_path / "reads.csv")


@pytest.mark.parametrize(
    "text, expected",
    [
        ("2023-11-14T22:13:20.123456789Z", 1700000000.123456789),
        ("2023-11-14T22:13:20Z", 1700000000.0),
        ("2023-11-14T23:13:20.5+01:00", 1700000000.5),
        ("2023-11-14T22:13:20.25", 1700000000.25),  # no offset: UTC
        ("2023-11-14 22:13:20z", 1700000000.0),
    ],
)
def test_iso_times(text, expected):
    assert iso_seconds(text) == pytest.approx(expected, abs=1e-6)


@pytest.mark.parametrize("text", ["2023-13-14T22:13:20Z", "yesterday", "1700000000", "", None, 1700000000])
def test_bad_iso_times(text):
    assert iso_seconds(text) is None


def test_channel_is_kept_and_gives_the_frequency_when_none(write_file, scene):
    text = EVENT % ',"channel":7' + "\n" + (EVENT % ',"channelIndex":8').replace('"frequency":915250,', "") + "\n"
    (reads, report), found = imported(write_file, scene, text)
    assert reads.channel_index.tolist() == [7, 8]
    assert reads.frequency_hz.tolist() == [915.25e6, 906.25e6]
    assert report.frequency_from == {"row": 1, "US channel plan": 1} and len(found) == 1


@pytest.mark.parametrize(
    "line, reason",
    [
        ('{"timestamp":"2023-11-14T22:13:21Z","eventType":"tagInv', "not JSON"),
        (EVENT.replace("45.0%s", "NaN"), "NaN or Infinity in JSON"),
        ('"just a string"', "not a JSON object"),
        (EVENT.replace("2023-11-14T22:13:20Z", "noon") % "", "time not ISO 8601"),
        (EVENT.replace('"epcHex":"E2801170",', "") % "", "no EPC"),
        (EVENT.replace('"epcHex":"E2801170"', '"epc":"***"') % "", "EPC not base64"),
        (EVENT.replace('"epcHex":"E2801170"', '"epcHex":"XY"') % "", "EPC not hex"),
        (EVENT.replace('"antennaPort":1', '"antennaPort":1.5') % "", "antenna not an integer"),
        (EVENT.replace('"antennaPort":1', '"antennaPort":5') % "", "antenna not in the scene"),
        (EVENT.replace(',"phaseAngle":45.0%s', ""), "no phaseAngle"),
        (EVENT.replace("45.0%s", "400.0"), "phase not a number in [0, 360] degrees"),
        (EVENT.replace("915250", '"fast"') % "", "frequency not a number (kHz)"),
        (EVENT.replace("915250", "915") % "", "frequency outside 100 MHz to 10 GHz"),
        (EVENT % ',"channel":0', "channel index not a positive integer"),
        (EVENT.replace("-5800", "true") % "", "RSSI not a number (centi-dBm)"),
    ],
)
def test_each_malformed_event_kind_is_declined_and_counted_with_its_line(write_file, scene, line, reason):
    good = EVENT % ""
    (reads, report), _ = imported(write_file, scene, good + "\n" + line + "\n\n" + good.replace("20Z", "21Z") + "\n")
    assert len(reads) == 2
    assert report.declined_by_reason() == {reason: 1}
    assert report.declined[next(iter(report.declined))].examples == {reason: [2]}


def test_not_utf8_is_a_clean_error(tmp_path, scene):
    path = tmp_path / "events.jsonl"
    path.write_bytes(b'{"eventType": "\xff"}\n')
    with pytest.raises(FormatError, match="not UTF-8"):
        import_impinj_iot([path], scene)


def test_an_array_line_holds_several_events(write_file, scene):
    (reads, report), _ = imported(write_file, scene, "[" + EVENT % "" + "," + (EVENT % "").replace("20Z", "22Z") + "]\n")
    assert (len(reads), report.rows) == (2, 2)
