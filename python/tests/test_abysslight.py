"""The Python package against the command it installs: same pixels, same bytes, the command's errors."""

import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest

import abysslight
from pngread import read_png

# The command the wheel installed beside this interpreter (the [project.scripts] entry point).
CLI = str(Path(sys.executable).parent / "abysslight")


def run_cli(*args, check=True):
    r = subprocess.run([CLI, *map(str, args)], capture_output=True, text=True)
    if check and r.returncode != 0:
        raise AssertionError(f"abysslight {' '.join(map(str, args))}: exit {r.returncode}\n{r.stderr}")
    return r


def pngs(folder):
    return sorted(Path(folder).rglob("*.png"))


def dive_folder(root, encode, frames=12, size="96x64", seed=3):
    """A simulated dive written by the command: water/, survey/ and truth/ under root."""
    run_cli("simulate", "--out", root, "--frames", frames, "--water-column", 5, "--size", size,
            "--seed", seed, "--encode", encode)
    return root


@pytest.fixture(scope="module")
def srgb_dive(tmp_path_factory):
    """An sRGB-encoded dive (PNGs with an sRGB chunk) and the command's default run over it."""
    root = dive_folder(tmp_path_factory.mktemp("srgb"), "srgb")
    out = root / "cli"
    run_cli("correct", "--water-column", root / "water", "--survey", root / "survey", "--out", out, "--quiet")
    return root, out


def engine_outputs(root, **options):
    """Engine over the dive's photos read by an independent PNG decoder; corrected images by tag."""
    water = [read_png(p) for p in pngs(root / "water")]
    engine = abysslight.Engine(scatter=abysslight.Scatter.from_frames(water), **options)
    out = {}
    for i, p in enumerate(pngs(root / "survey")):
        for c in engine.push(read_png(p), i):
            out[c.tag] = c
    for c in engine.finish():
        out[c.tag] = c
    return engine, out


def assert_same_pixels(engine_out, folder):
    files = pngs(folder)
    files = [f for f in files if "_abysslight" not in f.parts]
    assert len(files) == len(engine_out) > 0
    for i, f in enumerate(files):
        cli = read_png(f)
        mine = engine_out[i].image
        assert mine.shape == cli.shape and mine.dtype == cli.dtype
        assert np.array_equal(mine, cli), f"photo {i} ({f.name}) differs in {np.count_nonzero(mine != cli)} samples"


def test_engine_defaults_equal_the_command_defaults(srgb_dive):
    root, out = srgb_dive
    report = _report(out)
    # The command read the curve from the files (auto); arrays carry no file facts, so it is given explicitly.
    assert report["options"]["transfer"] == "srgb"
    engine, got = engine_outputs(root, transfer=report["options"]["transfer"])
    # The default: the window chosen per photo by the survey, in the engine as in the command.
    assert engine.window is None and report["window"]["rule"] == "auto" and report["window"]["n"] is None
    assert engine.method == "abyss"
    assert_same_pixels(got, out)
    assert got[0].image.dtype == np.uint8 and got[0].image.shape == (64, 96, 3)
    assert got[0].factor.dtype == np.float32 and got[0].factor.ndim == 3
    assert set(got[5].health) >= {"contamination", "level", "flags"}


def _report(out):
    import json

    return json.loads((out / "_abysslight" / "report.json").read_text())


def test_no_options_at_all_equal_the_command_on_files_that_declare_nothing_special(tmp_path):
    # A linear dive: the command's auto curve and the engine's auto (for arrays: what a file declaring nothing
    # gets, linear) agree, so Engine() with no options at all equals `abysslight correct` with none.
    root = dive_folder(tmp_path, "linear", frames=9, seed=5)
    out = tmp_path / "cli"
    run_cli("correct", "--water-column", root / "water", "--survey", root / "survey", "--out", out, "--quiet")
    assert _report(out)["options"]["transfer"] == "linear"
    engine, got = engine_outputs(root)
    assert engine.transfer == "linear"
    assert_same_pixels(got, out)


def test_options_by_name_match_the_command_and_change_the_result(srgb_dive, tmp_path):
    root, default_out = srgb_dive
    out = tmp_path / "paper"
    run_cli("correct", "--water-column", root / "water", "--survey", root / "survey", "--out", out, "--quiet",
            "--method", "paper", "--window", 5, "--transfer", "srgb")
    engine, paper = engine_outputs(root, method="paper", window=5, transfer="srgb")
    assert engine.downsample == 8  # the paper's blocks, as the command resolves auto for --method paper
    assert_same_pixels(paper, out)
    _, default = engine_outputs(root, transfer="srgb")
    assert any(not np.array_equal(paper[i].image, default[i].image) for i in default)
    _, wide = engine_outputs(root, transfer="srgb", window=9)
    assert any(not np.array_equal(wide[i].image, default[i].image) for i in default)
    # Negated flags both ways.
    _, a = engine_outputs(root, transfer="srgb", no_denoise=True)
    _, b = engine_outputs(root, transfer="srgb", denoise=False)
    assert all(np.array_equal(a[i].image, b[i].image) for i in a)
    assert any(not np.array_equal(a[i].image, default[i].image) for i in a)
    # The exposure levelling's switch by both names (this dive has no exposure jump: the same pixels either way).
    _, c = engine_outputs(root, transfer="srgb", no_level_exposures=True)
    _, d = engine_outputs(root, transfer="srgb", level_exposures=False)
    assert all(np.array_equal(c[i].image, d[i].image) for i in c)
    assert all(np.array_equal(c[i].image, default[i].image) for i in c)


def test_correct_writes_the_same_bytes_as_the_command(srgb_dive, tmp_path):
    root, cli_out = srgb_dive
    out = tmp_path / "py"
    seen = []
    report = abysslight.correct(survey=root / "survey", out=out, water_column=root / "water",
                                progress=lambda done, total, path, ok: seen.append((done, total, ok)))
    cli_files = [f for f in pngs(cli_out) if "_abysslight" not in f.parts]
    py_files = [f for f in pngs(out) if "_abysslight" not in f.parts]
    assert [f.name for f in py_files] == [f.name for f in cli_files] and len(cli_files) == 12
    for a, b in zip(py_files, cli_files):
        assert a.read_bytes() == b.read_bytes(), a.name
    assert report["corrected"] == 12 and report["failed"] == 0
    assert report["options"]["transfer"] == "srgb"
    assert seen[-1] == (12, 12, True) and len(seen) == 12


def test_engine_option_errors():
    with pytest.raises(TypeError, match="windw"):
        abysslight.Engine(windw=9)
    with pytest.raises(TypeError, match="resume"):
        abysslight.Engine(resume=True)
    with pytest.raises(ValueError, match="window must be an odd number"):
        abysslight.Engine(window=4)
    with pytest.raises(ValueError, match="invalid method"):
        abysslight.Engine(method="median")
    with pytest.raises(ValueError, match="invalid transfer"):
        abysslight.Engine(transfer="gamma")
    with pytest.raises(ValueError, match="contamination"):
        abysslight.Engine(contamination=0.7)
    with pytest.raises(ValueError, match="seafloor colour"):
        abysslight.Engine(seafloor_colour=(2.0, -1, 0.3, 9))
    with pytest.raises(ValueError, match="contamination"):
        abysslight.Engine(window=5, contamination=0.2)


def test_correct_option_errors(tmp_path):
    with pytest.raises(TypeError, match="no_such_option|no-such-option"):
        abysslight.correct(survey=tmp_path, out=tmp_path / "o", no_such_option=1, progress=False)
    with pytest.raises(TypeError, match="dry_run"):
        abysslight.correct(survey=tmp_path, out=tmp_path / "o", dry_run=True, progress=False)
    with pytest.raises(ValueError, match="survey is required"):
        abysslight.correct(out=tmp_path / "o", progress=False)
    with pytest.raises((OSError, ValueError), match="does-not-exist"):
        abysslight.correct(survey=tmp_path / "does-not-exist", out=tmp_path / "o", progress=False)


def test_photo_errors_leave_the_engine_usable():
    dive = abysslight.simulate(frames=5, water_column=3, width=48, height=32, seed=2)
    engine = abysslight.Engine(scatter=abysslight.Scatter.from_frames(dive["water_column"]), window=3)
    first = dive["survey"][0]
    assert engine.push(first, 0) == []
    bad = [
        (TypeError, "uint8 or uint16", first.astype(np.int32)),
        (ValueError, "outside 0..1", first.astype(np.float32)),
        (ValueError, "mission's photos are 32x48x3 uint8", (first / 255).astype(np.float32)),
        (TypeError, "numpy array", first.tolist()),
        (ValueError, "HxWx3", first[:, :, :2].copy()),
        (ValueError, "HxWx3", first[0, 0]),
        (ValueError, "HxWx3", np.zeros((2, 3, 4, 5), np.uint8)),
        (ValueError, "mission's photos are 32x48x3 uint8", first[:16]),
        (ValueError, "mission's photos are 32x48x3 uint8", first.astype(np.uint16)),
        (ValueError, "mission's photos are 32x48x3 uint8", first[:, :, 0].copy()),
    ]
    for kind, message, photo in bad:
        with pytest.raises(kind, match=message):
            engine.push(photo, "bad")
    # Nothing refused entered the window: the same photos give the same output as an engine that never saw them.
    clean = abysslight.Engine(scatter=abysslight.Scatter.from_frames(dive["water_column"]), window=3)
    clean.push(first, 0)
    a = engine.push(dive["survey"][1], 1) + engine.push(dive["survey"][2], 2) + engine.finish()
    b = clean.push(dive["survey"][1], 1) + clean.push(dive["survey"][2], 2) + clean.finish()
    assert [c.tag for c in a] == [0, 1, 2]
    assert all(np.array_equal(x.image, y.image) for x, y in zip(a, b))
    # A non-contiguous view is read (copied) correctly: the same as its contiguous copy.
    view = np.asfortranarray(first)
    e1, e2 = abysslight.Engine(window=1), abysslight.Engine(window=1)
    assert np.array_equal(e1.push(view, 0)[0].image, e2.push(first.copy(), 0)[0].image)


def test_scatter_and_mask_errors(tmp_path):
    dive = abysslight.simulate(frames=3, water_column=3, width=48, height=32)
    with pytest.raises(ValueError, match="no water-column frames"):
        abysslight.Scatter.from_frames([])
    with pytest.raises(ValueError, match="frame 1 is 16x48x3"):
        abysslight.Scatter.from_frames([dive["water_column"][0], dive["water_column"][1][:16]])
    with pytest.raises(TypeError, match="frame 0 must be uint8 or uint16"):
        abysslight.Scatter.from_frames([np.zeros((4, 4, 3), np.int32)])
    scatter = abysslight.Scatter.from_frames(dive["water_column"])
    with pytest.raises(ValueError, match="scatter"):
        abysslight.Engine(scatter=scatter).push(np.zeros((20, 20, 3), np.uint8), 0)
    with pytest.raises(ValueError, match="mask is 10x10"):
        abysslight.Engine(scatter=scatter, mask=abysslight.Mask(np.zeros((10, 10), bool)))
    with pytest.raises(ValueError, match="every pixel"):
        abysslight.Mask(np.ones((32, 48), bool))
    with pytest.raises(TypeError, match="bool or uint8"):
        abysslight.Mask(np.zeros((32, 48), np.float64))
    with pytest.raises(OSError, match="nowhere.png"):
        abysslight.Scatter.load(tmp_path / "nowhere.png")
    # Save and load round trip.
    scatter.save(tmp_path / "s.png")
    again = abysslight.Scatter.load(tmp_path / "s.png")
    assert np.array_equal(again.image, scatter.image) and scatter.shape == (32, 48, 3)


def test_mask_leaves_pixels_out_like_the_command(srgb_dive, tmp_path):
    root, _ = srgb_dive
    m = np.zeros((64, 96), bool)
    m[5:15, 70:90] = True  # an overlay's place
    mask_png = tmp_path / "mask.png"
    _write_png(mask_png, (m * 255).astype(np.uint8))
    out = tmp_path / "masked"
    # The window given: the command's `auto` surveys the photos first, which an engine fed one photo at a time
    # cannot; the mask is what is compared here.
    run_cli("correct", "--water-column", root / "water", "--survey", root / "survey", "--out", out, "--quiet",
            "--mask", mask_png, "--window", "7")
    mask = abysslight.Mask.load(mask_png)
    assert mask.count == m.sum() and np.array_equal(mask.array, m)
    water = [read_png(p) for p in pngs(root / "water")]
    engine = abysslight.Engine(scatter=abysslight.Scatter.from_frames(water), mask=abysslight.Mask(m),
                               transfer="srgb", window=7)
    assert engine.downsample == 8  # the paper's blocks with a mask, as the command resolves auto
    got = {}
    for i, p in enumerate(pngs(root / "survey")):
        got.update({c.tag: c for c in engine.push(read_png(p), i)})
    got.update({c.tag: c for c in engine.finish()})
    assert_same_pixels(got, out)


def _write_png(path, a, srgb=False):
    """An 8-bit grey or RGB PNG written here (filter 0), optionally declaring sRGB."""
    import struct
    import zlib

    def chunk(kind, body):
        return struct.pack(">I", len(body)) + kind + body + struct.pack(">I", zlib.crc32(kind + body))

    h, w = a.shape[:2]
    colour = 2 if a.ndim == 3 else 0
    raw = b"".join(b"\x00" + a[y].tobytes() for y in range(h))
    Path(path).write_bytes(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, colour, 0, 0, 0))
                           + (chunk(b"sRGB", b"\x00") if srgb else b"")
                           + chunk(b"IDAT", zlib.compress(raw)) + chunk(b"IEND", b""))


# ../shared beside the repository (ABYSSLIGHT_SHARED elsewhere).
SHARED = Path(os.environ.get("ABYSSLIGHT_SHARED", Path(__file__).resolve().parents[3] / "shared"))
REAL = SHARED / "data" / "real" / "nephrops-uwtv-burrows" / "run_20230604_1632"


@pytest.mark.skipif(os.environ.get("ABYSSLIGHT_REAL") != "1" or not REAL.is_dir(),
                    reason="needs ../shared/data/real and ABYSSLIGHT_REAL=1")
def test_engine_equals_the_command_on_a_real_set(tmp_path):
    # Real JPEGs decoded by the library and stored as sRGB PNGs (lossless outputs to compare), no water column.
    survey = tmp_path / "survey"
    survey.mkdir()
    photos = [abysslight.read(p) for p in sorted(REAL.glob("*.jpg"))[:30]]
    for i, p in enumerate(photos):
        _write_png(survey / f"{i:03}.png", p, srgb=True)
    out = tmp_path / "cli"
    run_cli("correct", "--survey", survey, "--out", out, "--quiet")
    assert _report(out)["options"]["transfer"] == "srgb"
    engine = abysslight.Engine(transfer="srgb")
    got = {}
    for i, p in enumerate(photos):
        got.update({c.tag: c for c in engine.push(p, i)})
    got.update({c.tag: c for c in engine.finish()})
    assert_same_pixels(got, out)


def _count_while(fn):
    """How many times another Python thread counted while fn() ran, and fn's result."""
    count, running, stop = [0], threading.Event(), threading.Event()

    def counter():
        running.set()
        while not stop.is_set():
            count[0] += 1

    t = threading.Thread(target=counter)
    t.start()
    running.wait()
    # The counter runs during fn only if fn releases the GIL (a call that holds it leaves the counter at 0).
    try:
        before = count[0]
        start = time.perf_counter()
        result = fn()
        elapsed = time.perf_counter() - start
        during = count[0] - before
    finally:
        stop.set()
        t.join()
    return during, elapsed, result


def test_the_gil_is_released_during_correct(tmp_path):
    root = dive_folder(tmp_path, "srgb", frames=30, size="320x240", seed=7)
    during, elapsed, report = _count_while(lambda: abysslight.correct(
        survey=root / "survey", out=tmp_path / "o", water_column=root / "water", progress=False))
    assert report["corrected"] == 30
    assert elapsed > 0.05 and during > 10_000, (during, elapsed)


def test_the_gil_is_released_during_push():
    dive = abysslight.simulate(frames=3, water_column=3, width=640, height=480, seed=4)
    engine = abysslight.Engine(window=1, transfer="linear")
    during, elapsed, out = _count_while(lambda: [engine.push(p, i) for i, p in enumerate(dive["survey"])])
    assert len(out) == 3 and during > 1_000, (during, elapsed)


def test_a_callback_exception_and_ctrl_c_stop_correct_cleanly(tmp_path):
    root = dive_folder(tmp_path, "srgb", frames=40, size="160x120", seed=9)
    args = dict(survey=root / "survey", water_column=root / "water")

    class Stop(Exception):
        pass

    def stop_at_5(done, total, path, ok):
        if done == 5:
            raise Stop()

    with pytest.raises(Stop):
        abysslight.correct(out=tmp_path / "a", progress=stop_at_5, **args)
    written = pngs(tmp_path / "a")
    assert 5 <= len(written) < 40
    for f in written:
        read_png(f)  # complete files only

    def ctrl_c_at_5(done, total, path, ok):
        if done == 5:
            os.kill(os.getpid(), signal.SIGINT)

    # Python's Ctrl-C handler, as in a terminal: a process started in the background (nohup, some CI runners)
    # inherits SIGINT ignored, and Python then installs none.
    before = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        with pytest.raises(KeyboardInterrupt):
            abysslight.correct(out=tmp_path / "b", progress=ctrl_c_at_5, **args)
    finally:
        signal.signal(signal.SIGINT, before)
    partial = pngs(tmp_path / "b")
    assert 5 <= len(partial) < 40
    # resume finishes it: the same bytes as an uninterrupted run.
    abysslight.correct(out=tmp_path / "b", resume=True, progress=False, **args)
    abysslight.correct(out=tmp_path / "c", progress=False, **args)
    b, c = pngs(tmp_path / "b"), pngs(tmp_path / "c")
    b = [f for f in b if "_abysslight" not in f.parts]
    c = [f for f in c if "_abysslight" not in f.parts]
    assert len(b) == len(c) == 40
    assert all(x.read_bytes() == y.read_bytes() for x, y in zip(b, c))


def test_the_installed_command(tmp_path):
    r = run_cli("window", "--contamination", "0.2")
    assert "n = 13" in r.stdout
    bad = run_cli("correct", "--windw", "3", check=False)
    assert bad.returncode == 2 and "unexpected argument '--windw'" in bad.stderr
    assert run_cli("--version").stdout.startswith("abysslight ")


def test_simulate_read_and_evaluate(srgb_dive, tmp_path):
    root, out = srgb_dive
    photo = abysslight.read(pngs(root / "survey")[0])
    assert np.array_equal(photo, read_png(pngs(root / "survey")[0]))
    dive = abysslight.simulate(frames=4, water_column=2, width=40, height=30, bit_depth=16, encode="srgb")
    assert dive["transfer"] == "srgb" and len(dive["survey"]) == 4 and len(dive["water_column"]) == 2
    assert dive["survey"][0].dtype == np.uint16 and dive["survey"][0].shape == (30, 40, 3)
    assert dive["albedo"][0].dtype == np.float32
    with pytest.raises(ValueError, match="bit_depth must be 8 or 16"):
        abysslight.simulate(bit_depth=12)
    ev = abysslight.evaluate([("raw", root / "survey"), ("abyss", out)], truth=root)
    sets = {s["label"]: s for s in ev["sets"]}
    assert sets["abyss"]["albedo_error"] < sets["raw"]["albedo_error"]
    assert all(0.0 <= s["clipped"] < 1.0 for s in ev["sets"])


def test_altitudes_choose_the_windows_in_the_engine_as_in_the_command(tmp_path):
    # A sledge whose altitude swings 3 ± 1.2 m, with the vehicle's log the simulator writes beside the photos.
    root = tmp_path / "dive"
    run_cli("simulate", "--out", root, "--frames", 30, "--water-column", 5, "--size", "96x64", "--seed", 4,
            "--encode", "srgb", "--altitude-swing", 1.2)
    nav = root / "navigation.csv"
    altitudes = {name: float(a) for name, a in (row.split(",") for row in nav.read_text().splitlines()[1:])}
    out = tmp_path / "cli"
    run_cli("correct", "--water-column", root / "water", "--survey", root / "survey", "--out", out,
            "--navigation", nav, "--quiet")
    frames = _report(out)["frames"]
    assert any("window_by_altitude" in f for f in frames), "no window chosen by altitude"
    assert [f["altitude"] for f in frames] == pytest.approx([altitudes[p.name] for p in pngs(root / "survey")])

    water = [read_png(p) for p in pngs(root / "water")]
    scatter = abysslight.Scatter.from_frames(water)
    engine = abysslight.Engine(scatter=scatter, transfer="srgb")
    got = {}
    photos = pngs(root / "survey")
    for i, p in enumerate(photos):
        for c in engine.push(read_png(p), i, altitude=altitudes[p.name]):
            got[c.tag] = c
    for c in engine.finish():
        got[c.tag] = c
    assert_same_pixels(got, out)
    for i, f in enumerate(frames):
        assert got[i].by_altitude == f.get("window_by_altitude"), f"photo {i}"
        assert got[i].altitude == pytest.approx(altitudes[photos[i].name])

    arrays = abysslight.correct_arrays([read_png(p) for p in photos], water_column=scatter, transfer="srgb",
                                       altitudes=[altitudes[p.name] for p in photos])
    assert all(np.array_equal(a, got[i].image) for i, a in enumerate(arrays))
    py_out = tmp_path / "py"
    abysslight.correct(water_column=root / "water", survey=root / "survey", out=py_out, navigation=nav)
    assert [read_png(p).tobytes() for p in pngs(py_out) if "_abysslight" not in p.parts] == \
        [got[i].image.tobytes() for i in range(len(photos))]

    # A log whose columns have names of their own, named by keyword (as a dict or as the command's text).
    renamed = tmp_path / "renamed.csv"
    renamed.write_text("frame;range\n" + "".join(f"{n};{a}\n" for n, a in altitudes.items()))
    for columns in ({"file": "frame", "altitude": "range"}, "file=frame,altitude=range"):
        named_out = tmp_path / f"named{len(str(columns))}"
        abysslight.correct(water_column=root / "water", survey=root / "survey", out=named_out, navigation=renamed,
                           navigation_columns=columns, navigation_clock_offset=0.0)
        assert [f.get("altitude") for f in _report(named_out)["frames"]] == [f["altitude"] for f in frames]
    with pytest.raises(ValueError, match="no column names the photo's file"):
        abysslight.correct(survey=root / "survey", out=tmp_path / "unnamed", navigation=renamed)

    # Errors: a list of altitudes of another length, an altitude that is not a positive number, a log for an
    # engine (it has no files to match), a log beside a cruise (each dive has its own).
    with pytest.raises(ValueError, match="altitudes lists 2 photos"):
        abysslight.correct_arrays([read_png(p) for p in photos[:3]], altitudes=[3.0, 3.1])
    with pytest.raises(ValueError, match="positive"):
        abysslight.Engine().push(read_png(photos[0]), 0, altitude=-2.0)
    with pytest.raises((TypeError, ValueError), match="navigation"):
        abysslight.Engine(navigation=str(nav))
    with pytest.raises(ValueError, match="cruise"):
        abysslight.correct(cruise=tmp_path, out=tmp_path / "c", navigation=nav)
