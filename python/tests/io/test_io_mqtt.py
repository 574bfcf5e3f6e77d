"""The MQTT payload (scattertrack.io.mqtt, docs/formats.md section 11)."""

import json

from scattertrack.io.appenders import TRACK_HEADER, track_cells
from scattertrack.io.mqtt import TOPIC, payload


def test_the_payload_is_the_track_row_with_null_for_nan():
    cells = track_cells(1796177306.9544981, "E200", [1.0, 2.0, 3.0000004], [float("nan")] * 3, [0.004, 0.004, 0.006])
    row = json.loads(payload(TRACK_HEADER, cells))
    assert list(row) == TRACK_HEADER
    assert row["time_s"] == 1796177306.954498 and row["epc"] == "E200" and row["z"] == 3.0
    assert row["vx"] is None and row["sz"] == 0.006
    assert TOPIC.format(epc="E200") == "scattertrack/tags/E200/estimate"
