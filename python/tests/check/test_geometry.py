"""The scene geometry check: warning lines, exit codes, twins (scenes written here)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from scattertrack import io
from scattertrack.check import check_scene, twin_positions
from scattertrack.cli import main

PAPER = [(1, [0.0, 0.0, 0.0]), (2, [0.0, 0.3, 0.0]), (3, [0.0, 0.8, 0.0]), (4, [0.8, 0.8, 0.0])]
BENCH = [(1, [0.0, 0.0, 0.15]), (2, [1.0, 0.05, 0.0]), (3, [0.05, 1.0, 0.4]), (4, [1.0, 1.0, 0.25])]


def write_scene(path: Path, antennas, region=None, dimensions=3, channels=()) -> Path:
    lines = [f'name = "test"', f"dimensions = {dimensions}"]
    if dimensions == 2:
        lines.append("plane_z = 0.0")
    lines += ["", "[reader]", 'kind = "cots"', "phase_sign = 1", 'phase_period = "2pi"', "phase_noise_rad = 0.1"]
    for antenna_id, position in antennas:
        lines += ["", "[[antennas]]", f"id = {antenna_id}", f"position = {position}", "phase_offset_rad = 0.5"]
    if region is not None:
        lines += ["", "[region]", f"min = {region[0]}", f"max = {region[1]}"]
    for i, f in enumerate(channels):
        lines += ["", "[[channel_offsets]]", f"frequency_hz = {f}", f"phase_offset_rad = {0.1 * i}"]
    path.write_text("\n".join(lines) + "\n")
    return path


def run(capsys, *argv) -> tuple[int, list[str]]:
    code = main([str(a) for a in argv])
    return code, capsys.readouterr().out.splitlines()


@pytest.fixture(scope="module")
def paper_scene(tmp_path_factory) -> Path:
    return write_scene(tmp_path_factory.mktemp("paper") / "scene.toml", PAPER, ([-0.5, -0.5, 0.05], [1.5, 1.5, 2.0]))


def test_paper_layout_warns_with_antennas_size_and_remedy(capsys, paper_scene):
    code, out = run(capsys, "check-scene", paper_scene)
    assert code == 0
    warnings = [line for line in out if line.startswith("warning:")]
    assert len(warnings) == 1, out
    line = warnings[0]
    assert "antennas 1, 2, 3 lie on one line" in line
    assert "integer of antenna 4 is free" in line
    assert "(median 3" in line and " cm away" in line  # a median of 30-something cm
    assert "remedy: move antenna 2 off the line through antennas 1, 2, 3 by >= " in line
    assert "enable hopping with calibrated channel offsets" in line
    assert out[-1].startswith("the layout does not fix a 3D position")


def test_bench_layout_gives_no_warning(capsys, tmp_path):
    scene = write_scene(tmp_path / "scene.toml", BENCH, ([-0.3, -0.3, 0.3], [1.3, 1.3, 1.6]))
    code, out = run(capsys, "check-scene", scene)
    assert code == 0
    assert not any(line.startswith("warning:") for line in out), out
    assert out[-1].startswith("the layout fixes a 3D position: no twin family within ")


def test_planar_2d_paper_layout_fixes_the_position(capsys, tmp_path):
    scene = write_scene(tmp_path / "scene.toml", PAPER, ([-0.5, -0.5, 0.0], [1.5, 1.5, 0.001]), dimensions=2)
    code, out = run(capsys, "check-scene", scene)
    assert code == 0 and not any(line.startswith("warning:") for line in out), out
    assert out[-1].startswith("the layout fixes a 2D position")


def test_coplanar_without_region_warns_about_the_mirror(tmp_path):
    antennas = [(1, [0.0, 0.0, 0.0]), (2, [1.0, 0.0, 0.0]), (3, [0.0, 1.0, 0.0]), (4, [0.7, 0.9, 0.0])]
    result = check_scene(io.read_scene(write_scene(tmp_path / "scene.toml", antennas)), remedies=False)
    mirror = [f for f in result.warnings if f.details["kind"] == "mirror"]
    assert len(mirror) == 1, result.lines()
    assert "antennas 1, 2, 3, 4 lie in one plane (z = 0.00 m)" in mirror[0].text
    assert "add a [region] that excludes the mirror side (z >= 0.05 or z <= -0.05" in mirror[0].text


def test_hopping_with_calibrated_offsets_removes_the_line_warning(tmp_path):
    channels = [902.75e6 + 0.5e6 * k for k in range(50)]
    path = write_scene(tmp_path / "scene.toml", PAPER, ([-0.5, -0.5, 0.05], [1.5, 1.5, 2.0]), channels=channels)
    result = check_scene(io.read_scene(path), remedies=False)  # no reads: the scene's calibrated channels
    assert not result.warnings, result.lines()
    assert "50 calibrated channels" in result.summary


def test_twin_positions_differ_by_whole_spacings(paper_scene):
    scene = io.read_scene(paper_scene)
    p = np.array([0.45, 0.35, 0.7])
    twins = twin_positions(scene, p)
    assert any(shift[:3] == [0, 0, 0] and shift[3] != 0 for _, shift, _ in twins)
    spacing = 299_792_458.0 / 915.25e6 / 2
    for position, shift, _ in twins:
        for (_, a), n in zip(PAPER, shift):
            delta = np.linalg.norm(position - a) - np.linalg.norm(p - a)
            assert abs(delta - n * spacing) < 1e-3 * spacing


def test_track_prints_the_warning_and_still_tracks(capsys, tmp_path):
    out_dir = tmp_path / "sim"
    assert main(["simulate", "--scenario", "glac-3d-arm-paper-layout", "--out", str(out_dir), "--duration", "2"]) == 0
    capsys.readouterr()
    code, out = run(capsys, "track", "--scene", out_dir / "scene.toml", "--reads", out_dir / "reads.csv", "--out", tmp_path / "t.csv", "--no-progress")
    assert code == 0
    warnings = [line for line in out if line.startswith("warning:")]
    geometry = [line for line in warnings if "antenna 4 is free" in line]
    # Besides the layout's warning, only the tracker's own: the twins leave
    # the track unresolved at its end.
    assert len(geometry) == 1, out
    assert all(line in geometry or "did not resolve" in line for line in warnings), out
    assert any(line.startswith("tracked with glac") for line in out)


def test_track_on_a_fixing_layout_prints_no_warning(capsys, tmp_path):
    out_dir = tmp_path / "sim"
    # Long enough for the candidates to resolve (glac-3d-arm's flat layout
    # takes 1-2 s of motion): then a clean recording prints no warning.
    assert main(["simulate", "--scenario", "glac-3d-arm", "--out", str(out_dir), "--duration", "8"]) == 0
    capsys.readouterr()
    code, out = run(capsys, "track", "--scene", out_dir / "scene.toml", "--reads", out_dir / "reads.csv", "--out", tmp_path / "t.csv", "--no-progress")
    assert code == 0
    assert not any("warning" in line for line in out), out


def test_check_scene_refuses_other_readers(capsys, tmp_path):
    path = tmp_path / "scene.toml"
    write_scene(path, PAPER)
    path.write_text(path.read_text().replace('kind = "cots"', 'kind = "lora-backscatter"'))
    code = main(["check-scene", str(path)])
    assert code == 2
