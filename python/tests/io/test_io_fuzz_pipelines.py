"""Fuzz-style checks of the helper and drone pipelines' readers: every malformed variant of a
valid file (truncated, swapped columns, empty, NaN/inf/huge/garbled cells, shuffled or repeated
rows, bytes that are not UTF-8) is either read, with every row used or declined and counted,
or rejected with a FormatError; never another exception.

The variants come from a fixed seed: the same cases on every run and machine.
"""

import random
import warnings

import pytest

from scattertrack.io import FormatError, read_features, read_frames, read_imu, read_scene

from scene_texts import helper_scene

HELPER_SCENE = helper_scene(3, """\
[helper]
bandwidth_hz = 100e6
n_subcarriers = 20

[region]
min = [-1.0, -1.0, 0.05]
max = [2.0, 2.0, 2.0]
""")

DRONE_SCENE = """\
name = "drone"
dimensions = 3

[reader]
kind = "lora-backscatter"

[region]
min = [-60.0, -60.0, -1.0]
max = [60.0, 60.0, 20.0]
"""

FRAMES = "time_s,epc,tx,rx,frequency_hz,h_re,h_im\n" + "".join(
    f"{0.01 * k:.6f},E2,0,{rx},{f!r},0.25,-0.1\n" for k in range(4) for rx in (1, 2, 3) for f in (902.5e6, 907.5e6)
)
IMU = "time_s,ax,ay,az,gx,gy,gz,baro_z\n" + "".join(f"{i / 100:.2f},0.1,0,9.81,0,0.01,0,{i * 0.01:.2f}\n" for i in range(20))
FEATURES = "time_s,range_m,azimuth_rad,elevation_rad,yaw_rad,range_sigma_m\n" + "".join(
    f"{0.05 + i / 10:.2f},10,0.5,0.1,{'' if i % 3 else 0.2},0.5\n" for i in range(10)
)

CELLS = ["nan", "inf", "-inf", "1e308", "1e300", "-1e300", "1e-320", "", "x", "\uff11", "1_0", "0x1F", "1e400",
         "-0", "+.5", " 1 ", '"1"', "1,5"]
"""Replacement cells: non-finite, huge, tiny, empty, garbled, quoted, with a comma."""

VARIANTS = 30
"""Mutated variants per file (each kind of mutation comes up several times)."""


def mutate(text: str, rng: random.Random) -> tuple[str | bytes, bool]:
    """One malformed variant of ``text`` and whether it keeps one data row per line (so counts can be checked)."""
    lines = text.rstrip("\n").split("\n")
    header, rows = lines[0].split(","), lines[1:]
    kind = rng.randrange(9)
    if kind == 0:  # truncated anywhere
        return text[: rng.randrange(len(text))], False
    if kind == 1:  # two header names swapped
        i, j = rng.sample(range(len(header)), 2)
        header[i], header[j] = header[j], header[i]
        return "\n".join([",".join(header), *rows]) + "\n", True
    if kind == 2:  # two whole columns swapped
        i, j = rng.sample(range(len(header)), 2)
        swapped = []
        for line in [",".join(header), *rows]:
            cells = line.split(",")
            cells[i], cells[j] = cells[j], cells[i]
            swapped.append(",".join(cells))
        return "\n".join(swapped) + "\n", True
    if kind == 3:  # empty, blank, BOM only, header only
        return rng.choice(["", "\n", "\ufeff", lines[0] + "\n"]), False
    if kind == 4:  # one cell replaced
        r, c = rng.randrange(len(rows)), rng.randrange(len(header))
        cells = rows[r].split(",")
        cells[c] = rng.choice(CELLS)
        rows[r] = ",".join(cells)
        return "\n".join([lines[0], *rows]) + "\n", '"' not in cells[c] and "," not in cells[c]
    if kind == 5:  # every cell of a column huge
        c = rng.randrange(len(header))
        value = rng.choice(["1e300", "-1e300", "1e200"])
        rows = [",".join(value if k == c else cell for k, cell in enumerate(row.split(","))) for row in rows]
        return "\n".join([lines[0], *rows]) + "\n", True
    if kind == 6:  # rows shuffled and some repeated
        rows = rows + rng.sample(rows, 3)
        rng.shuffle(rows)
        return "\n".join([lines[0], *rows]) + "\n", True
    if kind == 7:  # a byte that is not UTF-8
        data = text.encode()
        at = rng.randrange(len(data))
        return data[:at] + b"\xff\xfe" + data[at:], False
    # a row with a field too many or too few
    r = rng.randrange(len(rows))
    rows[r] = rows[r] + ",1" if rng.random() < 0.5 else rows[r].rsplit(",", 1)[0]
    return "\n".join([lines[0], *rows]) + "\n", False


def variants(text: str, seed: int):
    rng = random.Random(seed)
    return [mutate(text, rng) for _ in range(VARIANTS)]


def write(path, content) -> None:
    if isinstance(content, bytes):
        path.write_bytes(content)
    else:
        path.write_text(content, encoding="utf-8")


def read_or_reject(read, path):
    """The reader's result, or None for a FormatError naming ``path``; any other exception fails."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # InputWarnings are expected for odd but valid input
        try:
            return read(path)
        except FormatError as error:
            assert error.path == str(path), error
            assert str(error).startswith(str(path)), error
            return None


def data_rows(content) -> int:
    return len([line for line in content.split("\n")[1:] if line.strip()])


@pytest.mark.parametrize("index", range(VARIANTS))
def test_frames_variants(tmp_path, index):
    scene = tmp_path / "scene.toml"
    scene.write_text(HELPER_SCENE)
    content, one_row_per_line = variants(FRAMES, seed=5)[index]
    path = tmp_path / "frames.csv"
    write(path, content)
    frames = read_or_reject(lambda p: read_frames(p, read_scene(scene)), path)
    if frames is not None and one_row_per_line:
        assert len(frames) + frames.skipped.total == data_rows(content)


@pytest.mark.parametrize("index", range(VARIANTS))
def test_imu_variants(tmp_path, index):
    content, one_row_per_line = variants(IMU, seed=6)[index]
    path = tmp_path / "imu.csv"
    write(path, content)
    imu = read_or_reject(read_imu, path)
    if imu is not None and one_row_per_line:
        assert len(imu) + imu.skipped.total == data_rows(content)


@pytest.mark.parametrize("index", range(VARIANTS))
def test_features_variants(tmp_path, index):
    content, one_row_per_line = variants(FEATURES, seed=7)[index]
    path = tmp_path / "features.csv"
    write(path, content)
    features = read_or_reject(read_features, path)
    if features is not None and one_row_per_line:
        assert len(features) == data_rows(content)


def scene_variants(text: str, seed: int) -> list:
    """Truncations, numbers replaced by nan/inf/huge/text, keys dropped, bytes that are not UTF-8."""
    rng = random.Random(seed)
    out = []
    lines = text.split("\n")
    for _ in range(VARIANTS):
        kind = rng.randrange(4)
        if kind == 0:
            out.append(text[: rng.randrange(len(text))])
        elif kind == 1:
            numbered = [i for i, line in enumerate(lines) if any(ch.isdigit() for ch in line)]
            i = rng.choice(numbered)
            replaced = list(lines)
            replaced[i] = replaced[i].split("=")[0] + "= " + rng.choice(["nan", "inf", "1e400", "-1e300", '"x"', "[]",
                                                                      "[nan, 0, 0]", "[1e308, 1e308, 1e308]"])
            out.append("\n".join(replaced))
        elif kind == 2:
            keys = [i for i, line in enumerate(lines) if "=" in line]
            dropped = list(lines)
            del dropped[rng.choice(keys)]
            out.append("\n".join(dropped))
        else:
            data = text.encode()
            at = rng.randrange(len(data))
            out.append(data[:at] + b"\xc3" + data[at:])
    return out


@pytest.mark.parametrize("text", [HELPER_SCENE, DRONE_SCENE], ids=["helper", "drone"])
def test_scene_variants(tmp_path, text):
    for k, content in enumerate(scene_variants(text, seed=8)):
        path = tmp_path / f"scene{k}.toml"
        write(path, content)
        read_or_reject(read_scene, path)
