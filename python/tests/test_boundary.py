"""The Python boundary: options through the library's typed options, float and big-endian arrays, one call for a
list of arrays, exceptions by kind, ranges before allocation, one engine per mission and per thread."""

import os
import subprocess
import sys
import textwrap
import threading
from pathlib import Path

import numpy as np
import pytest

import abysslight

CLI = str(Path(sys.executable).parent / "abysslight")


def run_cli(*args):
    r = subprocess.run([CLI, *map(str, args)], capture_output=True, text=True)
    assert r.returncode == 0, f"abysslight {' '.join(map(str, args))}: exit {r.returncode}\n{r.stderr}"
    return r


def in_subprocess(code, timeout=120):
    """Run `code` in a fresh interpreter whose address space is capped at 4 GiB, so that an abort or a runaway
    allocation ends that process, not the test run. Returns (exit status, stdout, stderr)."""
    prelude = textwrap.dedent("""
        import resource
        resource.setrlimit(resource.RLIMIT_AS, (4 << 30, 4 << 30))
        import numpy as np
        import abysslight
    """)
    r = subprocess.run([sys.executable, "-c", prelude + textwrap.dedent(code)], capture_output=True, text=True,
                       timeout=timeout)
    return r.returncode, r.stdout, r.stderr


@pytest.fixture(scope="module")
def small_dive():
    return abysslight.simulate(frames=9, water_column=3, width=48, height=32, seed=6)


# Options: through the library's typed options, not the command line's parser.

def test_option_values_of_the_wrong_type_are_type_errors():
    # Bytes were a sequence of numbers joined into a string: window=b"7" became window 55.
    with pytest.raises(TypeError, match="window"):
        abysslight.Engine(window=b"7")
    with pytest.raises(TypeError, match="denoise"):
        abysslight.Engine(denoise="yes")
    with pytest.raises(TypeError, match="window"):
        abysslight.Engine(window=[7])
    with pytest.raises(TypeError, match="no_denoise"):
        abysslight.Engine(no_denoise=1)


def test_options_by_value_and_their_defaults():
    assert abysslight.Engine().window is None  # auto: the survey chooses per photo
    assert abysslight.Engine(window=np.int64(9)).window == 9
    assert abysslight.Engine(window="auto").window is None
    assert abysslight.Engine(window=None).window is None
    assert abysslight.Engine(contamination=0.3).window == abysslight.Engine(contamination=np.float32(0.3)).window
    assert abysslight.Engine(seafloor_colour=(0.42, 0.36, 0.28)).window is None
    assert abysslight.Engine(seafloor_color="#8a7560").window is None
    with pytest.raises(ValueError, match="either denoise or no_denoise"):
        abysslight.Engine(denoise=True, no_denoise=True)
    with pytest.raises(ValueError, match="risk"):
        abysslight.Engine(risk=float("nan"))
    with pytest.raises(ValueError, match="window"):
        abysslight.Engine(window="seven")


def test_unknown_options_name_the_accepted_ones(tmp_path):
    with pytest.raises(TypeError, match=r"windw.*accepted.*contamination.*window"):
        abysslight.Engine(windw=9)
    with pytest.raises(TypeError, match=r"no_such_option.*accepted.*survey.*window"):
        abysslight.correct(survey=tmp_path, out=tmp_path / "o", no_such_option=1, progress=False)
    # The engine takes the method's options only, correct() every option of the command but its own flags.
    with pytest.raises(TypeError, match="survey"):
        abysslight.Engine(survey=tmp_path)
    for flag in ["watch", "dry_run", "quiet"]:
        with pytest.raises(TypeError, match=flag):
            abysslight.correct(survey=tmp_path, out=tmp_path / "o", progress=False, **{flag: True})


def test_correct_takes_a_config_file_and_overrides_it(tmp_path):
    cfg = tmp_path / "dive.toml"
    cfg.write_text('window = 4\n')
    with pytest.raises(ValueError, match="window must be an odd number"):
        abysslight.correct(config=cfg, survey=tmp_path, out=tmp_path / "o", progress=False)
    # A keyword overrides the file; a contamination given undoes the file's window, as the command's flag does.
    with pytest.raises(ValueError, match="survey is required"):
        abysslight.correct(config=cfg, window=5, progress=False)
    cfg.write_text('windw = 9\n')
    with pytest.raises(ValueError, match="windw"):
        abysslight.correct(config=cfg, survey=tmp_path, out=tmp_path / "o", progress=False)


# Arrays: float in 0..1 and big-endian.

def test_float_arrays_in_and_out(small_dive):
    photos16 = [(p.astype(np.uint16) * 257) for p in small_dive["survey"]]
    want = abysslight.correct_arrays(photos16, window=3)
    for dtype in [np.float32, np.float64]:
        photos = [(p / 65535.0).astype(dtype) for p in photos16]
        got = abysslight.correct_arrays(photos, window=3)
        assert len(got) == len(photos)
        for g, w in zip(got, want):
            assert g.dtype == dtype and g.shape == w.shape
            assert np.all((g >= 0) & (g <= 1))
            assert np.max(np.abs(g - w / 65535.0)) < 1e-6
    engine = abysslight.Engine(window=1)
    with pytest.raises(ValueError, match=r"0\.\.1|0 to 1"):
        engine.push(np.full((32, 48, 3), 1.5, np.float32), 0)
    with pytest.raises(ValueError, match="NaN|nan"):
        engine.push(np.full((32, 48, 3), np.nan, np.float32), 0)
    with pytest.raises(TypeError, match="float16"):
        engine.push(np.zeros((32, 48, 3), np.float16), 0)


def test_big_endian_arrays_are_read_as_their_values(small_dive):
    native = [p.astype(np.uint16) * 257 for p in small_dive["survey"]]
    swapped = [p.astype(">u2") for p in native]
    assert swapped[0].dtype.byteorder == ">"
    a = abysslight.correct_arrays(native, window=3)
    b = abysslight.correct_arrays(swapped, window=3)
    assert all(np.array_equal(x, y) for x, y in zip(a, b))
    s1 = abysslight.Scatter.from_frames([p.astype(np.uint16) for p in small_dive["water_column"]])
    s2 = abysslight.Scatter.from_frames([p.astype(">u2") for p in small_dive["water_column"]])
    assert np.array_equal(s1.image, s2.image)


# One call for a notebook.

def test_correct_arrays_equals_the_engine(small_dive):
    water, photos = small_dive["water_column"], small_dive["survey"]
    got = abysslight.correct_arrays(photos, water_column=water, transfer="linear")
    engine = abysslight.Engine(scatter=abysslight.Scatter.from_frames(water), transfer="linear")
    want = {}
    for i, p in enumerate(photos):
        want.update({c.tag: c.image for c in engine.push(p, i)})
    want.update({c.tag: c.image for c in engine.finish()})
    assert len(got) == len(photos) == len(want)
    assert all(np.array_equal(got[i], want[i]) for i in range(len(photos)))
    assert all(g.dtype == np.uint8 and g.shape == p.shape for g, p in zip(got, photos))
    # S given as a Scatter, and no water column at all.
    again = abysslight.correct_arrays(photos, water_column=abysslight.Scatter.from_frames(water))
    assert all(np.array_equal(x, y) for x, y in zip(got, again))
    bare = abysslight.correct_arrays(photos)
    assert any(not np.array_equal(x, y) for x, y in zip(got, bare))
    with pytest.raises(ValueError, match="photo 2"):
        abysslight.correct_arrays([photos[0], photos[1], photos[2][:16]])
    with pytest.raises(ValueError, match="no photos"):
        abysslight.correct_arrays([])
    with pytest.raises(TypeError, match="windw"):
        abysslight.correct_arrays(photos, windw=3)


# Exceptions by kind; arrays past the decoders' limits refused before any allocation.

def test_huge_views_are_refused_without_killing_the_interpreter():
    code, out, err = in_subprocess("""
        big = np.broadcast_to(np.array([100], np.uint8), (100000, 100000, 3))
        mask = np.broadcast_to(np.array([False]), (100000, 100000))
        wide = np.zeros((1, (1 << 20) + 1), np.uint8)
        for name, call in [("push", lambda: abysslight.Engine().push(big, 0)),
                           ("mask", lambda: abysslight.Mask(mask)),
                           ("scatter", lambda: abysslight.Scatter.from_frames([big])),
                           ("wide", lambda: abysslight.Engine().push(wide, 0)),
                           ("arrays", lambda: abysslight.correct_arrays([big]))]:
            try:
                call()
                print(name, "accepted")
            except ValueError as e:
                print(name, "ValueError", e)
    """)
    assert code == 0, (code, err[-2000:])
    lines = out.splitlines()
    assert len(lines) == 5 and all(" ValueError " in line for line in lines), out
    assert "100000x100000" in lines[0] and "268435456" in lines[0], lines[0]


def test_simulate_and_evaluate_take_the_command_s_ranges(tmp_path):
    run_cli("simulate", "--out", tmp_path / "d", "--frames", 4, "--water-column", 1, "--size", "48x32")
    code, out, err = in_subprocess(f"""
        calls = [
            lambda: abysslight.simulate(width=100000, height=100000, frames=2, water_column=1),
            lambda: abysslight.simulate(frames=10**9, width=16, height=16),
            lambda: abysslight.simulate(width=2**62),
            lambda: abysslight.simulate(noise=float("nan"), frames=2, water_column=1),
            lambda: abysslight.evaluate([("raw", {str(tmp_path / "d" / "survey")!r})], cell=0.001),
        ]
        for call in calls:
            try:
                call()
                print("accepted")
            except ValueError as e:
                print("ValueError", e)
    """)
    assert code == 0, (code, err[-2000:])
    lines = out.splitlines()
    assert lines == [
        "ValueError size (width) must be within 8..=16384, got 100000",
        "ValueError frames must be within 1..=1000000, got 1000000000",
        "ValueError size (width) must be within 8..=16384, got 4611686018427387904",
        "ValueError noise must be within 0..=100, got NaN",
        "ValueError cell must be within 1..=1000000, got 0.001",
    ], out
    # The command gives the same messages.
    r = subprocess.run([CLI, "simulate", "--out", tmp_path / "x", "--frames", "1000000000"], capture_output=True,
                       text=True)
    assert r.returncode == 2 and "--frames must be within 1..=1000000, got 1000000000" in r.stderr


def test_a_dive_too_large_for_memory_is_a_memory_error():
    code, out, err = in_subprocess("""
        try:
            abysslight.simulate(frames=1_000_000, water_column=1, width=16384, height=16384)
        except MemoryError as e:
            print("MemoryError", e)
    """)
    assert code == 0 and out.startswith("MemoryError"), (code, out, err[-2000:])


def test_error_kinds(tmp_path):
    with pytest.raises(OSError):
        abysslight.Scatter.load(tmp_path / "nowhere.png")
    with pytest.raises(OSError, match="does-not-exist"):
        abysslight.correct(survey=tmp_path / "does-not-exist", out=tmp_path / "o", progress=False)
    (tmp_path / "bad.png").write_bytes(b"\x89PNG\r\n\x1a\nnot a png")
    with pytest.raises(ValueError, match="bad.png"):
        abysslight.read(tmp_path / "bad.png")


def test_a_scatter_image_that_is_a_fifo_is_refused_not_waited_on(tmp_path):
    # Opening a FIFO waits for a writer: load must refuse it by name before opening it.
    fifo = tmp_path / "scatter.png"
    os.mkfifo(fifo)
    code, out, err = in_subprocess(f"""
        try:
            abysslight.Scatter.load({str(fifo)!r})
        except Exception as e:
            print(type(e).__name__, e)
    """, timeout=60)
    assert code == 0 and "FIFO" in out and "scatter.png" in out, (code, out, err[-2000:])


# correct(cruise=...).

def test_correct_runs_a_cruise(tmp_path):
    cruise = tmp_path / "cruise"
    for i, dive in enumerate(["dive2", "dive10"]):
        run_cli("simulate", "--out", cruise / dive, "--frames", 5, "--water-column", 2, "--size", "48x32",
                "--seed", 4 + i)
        (cruise / dive / "water").rename(cruise / dive / "water-column")
    result = abysslight.correct(cruise=cruise, out=tmp_path / "out", window=3, progress=False)
    assert list(result["dives"]) == ["dive2", "dive10"] and result["failed"] == {}
    for dive in ["dive2", "dive10"]:
        report = result["dives"][dive]
        assert report["corrected"] == 5 and report["failed"] == 0
        assert len(list((tmp_path / "out" / dive).glob("*.png"))) == 5
    # The command's run of the same cruise writes the same bytes.
    run_cli("correct", "--cruise", cruise, "--out", tmp_path / "cli", "--window", 3, "--quiet")
    for f in sorted((tmp_path / "cli").rglob("*.png")):
        if "_abysslight" in f.parts:
            continue
        assert f.read_bytes() == (tmp_path / "out" / f.relative_to(tmp_path / "cli")).read_bytes(), f
    with pytest.raises(ValueError, match="cruise"):
        abysslight.correct(cruise=cruise, survey=cruise / "dive2" / "survey", out=tmp_path / "o2", progress=False)


# One engine: one mission, one thread at a time.

def test_an_engine_after_finish_refuses_photos(small_dive):
    engine = abysslight.Engine(window=3)
    for i, p in enumerate(small_dive["survey"][:4]):
        engine.push(p, i)
    assert len(engine.finish()) >= 1
    with pytest.raises(RuntimeError, match="one mission"):
        engine.push(small_dive["survey"][4], 4)
    with pytest.raises(RuntimeError, match="one mission"):
        engine.finish()


def test_an_engine_used_from_two_threads_at_once_says_so():
    dive = abysslight.simulate(frames=2, water_column=1, width=640, height=480, seed=8)
    engine = abysslight.Engine(window=1, transfer="linear")
    errors, stop = [], threading.Event()

    def busy():
        try:
            for _ in range(15):
                engine.push(dive["survey"][0], "a")
        except RuntimeError as e:
            errors.append(str(e))
        finally:
            stop.set()

    t = threading.Thread(target=busy)
    t.start()
    while not stop.is_set() and not errors:
        try:
            engine.push(dive["survey"][1], "b")
        except RuntimeError as e:
            errors.append(str(e))
    t.join()
    assert errors and "thread" in errors[0] and "one mission" in errors[0], errors
