"""``scattertrack track`` streams CSV in and out, printing and writing what the in-memory path does."""

import pytest

from scattertrack.cli import main


@pytest.fixture(scope="module")
def sessions(tmp_path_factory):
    folders = {}
    for name in ("glac-3d-arm-5tags", "glac-2d-40cms-hopping", "glac-2d-10cms"):
        folder = tmp_path_factory.mktemp(name)
        assert main(["simulate", "--scenario", name, "--out", str(folder), "--duration", "4"]) == 0
        folders[name] = folder
    return folders


def track(capsys, monkeypatch, folder, out, stream: bool, reads=None):
    monkeypatch.setenv("SCATTERTRACK_STREAM", "1" if stream else "0")
    code = main(["track", "--scene", str(folder / "scene.toml"), "--reads", str(reads or folder / "reads.csv"),
                 "--out", str(out)])
    captured = capsys.readouterr()
    lines = [line.replace(str(out), "OUT") for line in captured.out.splitlines() if "speed:" not in line]
    return code, lines, captured.err


@pytest.mark.parametrize("name", ["glac-3d-arm-5tags", "glac-2d-40cms-hopping", "glac-2d-10cms"])
def test_streamed_and_in_memory_runs_agree(capsys, monkeypatch, sessions, tmp_path, name):
    folder = sessions[name]
    streamed = track(capsys, monkeypatch, folder, tmp_path / "stream.csv", stream=True)
    in_memory = track(capsys, monkeypatch, folder, tmp_path / "memory.csv", stream=False)
    assert streamed == in_memory
    assert (tmp_path / "stream.csv").read_bytes() == (tmp_path / "memory.csv").read_bytes()


def test_a_clock_jump_back_is_tracked_whole_with_a_warning(capsys, monkeypatch, sessions, tmp_path):
    folder = sessions["glac-2d-10cms"]
    lines = (folder / "reads.csv").read_text().splitlines()
    lines.append(lines[5])  # a copy of an early row at the end: a jump back of about 4 s
    reads = tmp_path / "reads.csv"
    reads.write_text("\n".join(lines) + "\n")
    code, streamed, err = track(capsys, monkeypatch, folder, tmp_path / "stream.csv", stream=True, reads=reads)
    assert code == 0
    assert streamed[0].startswith("warning: ") and "reading the whole file instead" in streamed[0]
    _, in_memory, _ = track(capsys, monkeypatch, folder, tmp_path / "memory.csv", stream=False, reads=reads)
    assert streamed[1:] == in_memory
    assert (tmp_path / "stream.csv").read_bytes() == (tmp_path / "memory.csv").read_bytes()
