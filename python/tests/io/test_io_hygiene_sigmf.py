"""Helper SigMF recordings against their own antenna list, the scene and the calibration:
errors name the file and key, disagreements with the scene are InputWarnings."""

import json
import shutil
import warnings

import numpy as np
import pytest

from scattertrack import dsp, io
from scattertrack.io import FormatError, InputWarning
from scattertrack.io.types import Antenna, Reader, Region, Scene
from scattertrack.sim import iq

TX = np.array([0.4, 0.4, 0.0])
RX = np.array([[0.0, 0.4, 0.0], [0.8, 0.4, 0.0], [0.4, 0.0, 0.0], [0.4, 0.8, 0.0]])


def helper_scene() -> Scene:
    antennas = [Antenna(0, TX.copy(), role="tx")] + [Antenna(i + 1, p.copy(), role="rx") for i, p in enumerate(RX)]
    region = Region(np.array([-1.0, -1.0, 0.05]), np.array([2.0, 2.0, 2.0]))
    return Scene("helper", 3, Reader(kind="sdr-helper"), antennas, region=region)


@pytest.fixture(scope="module")
def written(tmp_path_factory):
    """A short simulated recording and its calibration (4 replies), read-only."""
    sim = iq.simulate_iq(helper_scene(), {"E1": {"kind": "static", "position": [0.55, 0.30, 0.60]}}, seed=1,
                         duration_s=0.014)
    return iq.write_iq_simulation(sim, tmp_path_factory.mktemp("sigmf") / "run")


@pytest.fixture
def copy(written, tmp_path):
    """Fresh copies of the recording and calibration files; returns the folder."""
    for name in ("recording", "calibration"):
        for suffix in (".sigmf-meta", ".sigmf-data"):
            shutil.copy(written / f"{name}{suffix}", tmp_path / f"{name}{suffix}")
    return tmp_path


def edit_meta(meta, change):
    document = json.loads(meta.read_text())
    change(document["global"])
    meta.write_text(json.dumps(document))


def input_warnings(call) -> list[InputWarning]:
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        call()
    return [w.message for w in caught if issubclass(w.category, InputWarning)]


ANTENNAS = "scattertrack:antennas"


@pytest.mark.parametrize(
    "change, column, fragment",
    [
        (lambda g: g.__setitem__(ANTENNAS, "tx at 0.4"), f"global.{ANTENNAS}", "non-empty list"),
        (lambda g: g[ANTENNAS][1].pop("position"), f"global.{ANTENNAS}[1].position", "3 finite numbers"),
        (lambda g: g[ANTENNAS][1].__setitem__("position", [0, 1]), f"global.{ANTENNAS}[1].position", "3 finite"),
        (lambda g: g[ANTENNAS][2].__setitem__("id", "2"), f"global.{ANTENNAS}[2].id", "not an integer"),
        (lambda g: g[ANTENNAS][2].__setitem__("id", 1), f"global.{ANTENNAS}[2].id", "listed twice"),
        (lambda g: g[ANTENNAS][3].__setitem__("role", "txrx"), f"global.{ANTENNAS}[3].role", "'tx' or 'rx'"),
        (lambda g: g[ANTENNAS][3].__setitem__("role", "tx"), f"global.{ANTENNAS}[3].role",
         "antenna 3 is listed as 'tx' but scattertrack:channels makes it 'rx'"),
        (lambda g: g[ANTENNAS].pop(0), f"global.{ANTENNAS}", "antenna 0 (scattertrack:tx_id) is not listed"),
    ],
    ids=["not-a-list", "no-position", "short-position", "text-id", "repeated-id", "bad-role", "tx-as-rx", "no-tx"],
)
def test_bad_antenna_list_names_the_key(copy, change, column, fragment):
    meta = copy / "recording.sigmf-meta"
    edit_meta(meta, change)
    with pytest.raises(FormatError) as error:
        io.read_sigmf(meta)
    assert (error.value.path, error.value.column) == (str(meta), column)
    assert fragment in error.value.message


def test_a_scene_tx_named_as_an_rx_is_rejected(copy):
    scene = helper_scene()
    scene.antennas[0].role, scene.antennas[1].role = "rx", "tx"
    with pytest.raises(FormatError, match="antenna 0 is not a 'tx' antenna") as error:
        dsp.read_sigmf_frames(copy / "recording.sigmf-meta", scene)
    assert error.value.column == "global.scattertrack:tx_id"


@pytest.mark.parametrize("moved_m, warned", [(0.04, False), (0.06, True)])
def test_scene_positions_beyond_5_cm_of_the_recordings_warn(copy, moved_m, warned):
    scene = helper_scene()
    scene.antennas[2].position = scene.antennas[2].position + [0.0, moved_m, 0.0]
    meta = copy / "recording.sigmf-meta"
    found = input_warnings(lambda: dsp.estimate_sigmf(meta, scene))
    assert [(w.path, w.column) for w in found] == ([(str(meta), f"global.{ANTENNAS}[2].position")] if warned else [])
    if warned:
        assert "antenna 2 is at (0.800, 0.400, 0.000) m in the recording but at (0.800, 0.460, 0.000) m" in found[0].message
        assert "6.0 cm apart" in found[0].message


def test_scene_helper_table_other_than_the_recordings_warns(copy):
    scene = helper_scene()
    scene.extra["helper"] = {"bandwidth_hz": 50e6, "n_subcarriers": 20}
    (warning,) = input_warnings(lambda: dsp.estimate_sigmf(copy / "recording.sigmf-meta", scene))
    assert warning.column == "global.scattertrack:bandwidth_hz" and "[helper] bandwidth_hz = 50000000.0" in warning.message


def test_a_calibration_of_other_receivers_is_rejected_naming_it(copy):
    calibration = dsp.calibrate_sigmf(copy / "calibration.sigmf-meta", helper_scene())
    calibration.rx_ids = [1, 2, 3]
    with pytest.raises(FormatError) as error:
        dsp.estimate_sigmf(copy / "recording.sigmf-meta", helper_scene(), calibration)
    assert error.value.path == str(copy / "calibration.sigmf-meta")
    assert error.value.column == "global.scattertrack:channels" and "another set-up" in error.value.message


@pytest.mark.parametrize("value, fragment", [(None, "missing"), ([0.5, "x", 0.6], "3 finite numbers")])
def test_a_calibration_without_its_tag_position_is_rejected(copy, value, fragment):
    meta = copy / "calibration.sigmf-meta"
    if value is None:
        edit_meta(meta, lambda g: g.pop("scattertrack:calibration"))
    else:
        edit_meta(meta, lambda g: g["scattertrack:calibration"].__setitem__("tag_position", value))
    with pytest.raises(FormatError) as error:
        dsp.estimate_sigmf(copy / "recording.sigmf-meta", helper_scene(), meta)
    assert (error.value.path, error.value.column) == (str(meta), "global.scattertrack:calibration.tag_position")
    assert fragment in error.value.message


def test_a_missing_calibration_recording_is_rejected(copy):
    with pytest.raises(FormatError, match="metadata file not found") as error:
        dsp.estimate_sigmf(copy / "recording.sigmf-meta", helper_scene(), copy / "elsewhere.sigmf-meta")
    assert error.value.path == str(copy / "elsewhere.sigmf-meta")


def test_the_written_recording_is_quiet(written):
    assert input_warnings(lambda: dsp.estimate_sigmf(written / "recording.sigmf-meta", helper_scene(),
                                                    written / "calibration.sigmf-meta")) == []
