"""What correct() says and how it waits: the end-of-run summary in the log, keyword names in messages, strict=True,
altitudes as a log gives them, a clean namespace, and a calling thread that sleeps while the run works."""

import logging
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest

import abysslight

CLI = str(Path(sys.executable).parent / "abysslight")


def run_cli(*args):
    return subprocess.run([CLI, *map(str, args)], capture_output=True, text=True)


@pytest.fixture(scope="module")
def short_dive(tmp_path_factory):
    """A mission of 12 photos (as MBARI's) under a slow camera over a dense nodule field: the run flags photos."""
    root = tmp_path_factory.mktemp("short")
    r = run_cli("simulate", "--out", root, "--frames", 12, "--water-column", 4, "--size", "160x120", "--seed", 5,
                "--overlap", 0.9, "--contamination", 0.4)
    assert r.returncode == 0, r.stderr
    return root


def test_the_calling_thread_sleeps_while_the_run_works(tmp_path):
    # Before: without a callback the calling thread polled a closed channel, busy, for the whole run (1.4-1.5x
    # the command's CPU time on 2 cores). Its own CPU time must be a small part of the wall time.
    root = tmp_path / "dive"
    assert run_cli("simulate", "--out", root, "--frames", 40, "--water-column", 4, "--size", "320x240").returncode == 0
    for progress in (False, None):
        cpu0, wall0 = time.thread_time(), time.perf_counter()
        abysslight.correct(survey=root / "survey", water_column=root / "water", out=tmp_path / f"o{progress}",
                           progress=progress, threads=1)
        cpu, wall = time.thread_time() - cpu0, time.perf_counter() - wall0
        assert wall > 0.2, f"the run is too short to tell ({wall:.2f} s)"
        assert cpu < 0.25 * wall, f"progress={progress}: the calling thread used {cpu:.2f} s of CPU in {wall:.2f} s"


def test_the_summary_is_logged_as_the_command_prints_it(short_dive, tmp_path, caplog):
    root = short_dive
    cli = run_cli("correct", "--survey", root / "survey", "--water-column", root / "water", "--out", tmp_path / "cli")
    assert cli.returncode == 0, cli.stderr
    cli_lines = [l[len("abysslight: "):] for l in cli.stderr.splitlines() if l.startswith("abysslight: ")]
    with caplog.at_level(logging.INFO, logger="abysslight"):
        report = abysslight.correct(survey=root / "survey", water_column=root / "water", out=tmp_path / "py",
                                    progress=False)
    flagged = [f for f in report["frames"] if f["health"]["flags"]]
    assert flagged, "the short mission is expected to raise flags"
    records = [r for r in caplog.records if r.name == "abysslight"]
    said = [r.getMessage() for r in records]
    # The flags line, word for word as the command prints it, at WARNING (seen without any logging set-up).
    monitor = next(l for l in cli_lines if "photos flagged as likely wrong" in l)
    hit = [r for r in records if r.getMessage() == monitor]
    assert hit and all(r.levelno == logging.WARNING for r in hit), said
    assert any(m.startswith("12 of 12 photos corrected in") for m in said), said
    assert any(m.startswith("  flagged #1 ") for m in said), said
    assert any("where to look:" in m and "overview.png" in m for m in said), said
    # A clean run's summary at INFO.
    caplog.clear()
    with caplog.at_level(logging.INFO, logger="abysslight"):
        clean = abysslight.correct(survey=root / "survey", water_column=root / "water", out=tmp_path / "py5",
                                   window=5, progress=False)
    lines = [r for r in caplog.records if "photos corrected in" in r.getMessage()]
    assert len(lines) == 1
    expected = logging.WARNING if any(f["health"]["flags"] for f in clean["frames"]) else logging.INFO
    assert lines[0].levelno == expected


def test_strict_raises_after_the_run_and_the_command_exits_3(short_dive, tmp_path):
    root = short_dive
    with pytest.raises(abysslight.FlaggedPhotosError, match="photos flagged as likely wrong") as e:
        abysslight.correct(survey=root / "survey", water_column=root / "water", out=tmp_path / "py",
                           progress=False, strict=True)
    report = e.value.report
    assert report["corrected"] == 12 and report["options"]["strict"] is True
    assert len(list((tmp_path / "py").glob("*.png"))) == 12, "every photo is written before the error"
    # From a config file too.
    cfg = tmp_path / "strict.toml"
    cfg.write_text("strict = true\n")
    with pytest.raises(abysslight.FlaggedPhotosError):
        abysslight.correct(config=cfg, survey=root / "survey", water_column=root / "water", out=tmp_path / "c",
                           progress=False)
    r = run_cli("correct", "--survey", root / "survey", "--water-column", root / "water", "--out", tmp_path / "cli",
                "--strict", "-q")
    assert r.returncode == 3, r.stderr
    assert run_cli("correct", "--survey", root / "survey", "--water-column", root / "water", "--out",
                   tmp_path / "cli2", "-q").returncode == 0


def test_messages_name_keywords_and_guess_a_misspelt_one(tmp_path):
    with pytest.raises(ValueError) as e:
        abysslight.correct(survey=tmp_path, out=tmp_path / "o", window=4, progress=False)
    assert "window must be an odd number" in str(e.value) and "--" not in str(e.value), str(e.value)
    with pytest.raises(ValueError) as e:
        abysslight.Engine(window=5, contamination=0.2)
    assert "--" not in str(e.value) and "window" in str(e.value), str(e.value)
    with pytest.raises(TypeError, match="did you mean `window`"):
        abysslight.correct(survey=tmp_path, out=tmp_path / "o", windw=9, progress=False)
    with pytest.raises(TypeError, match="did you mean `transfer`"):
        abysslight.Engine(tranfser="srgb")
    with pytest.raises(TypeError, match="did you mean `seafloor_colour`"):
        abysslight.Engine(seafloor_colourr="grey")
    with pytest.raises(TypeError) as e:
        abysslight.Engine(zzzzzzzz=1)
    assert "did you mean" not in str(e.value) and "accepted:" in str(e.value)


def test_the_namespace_is_what_all_lists():
    public = {n for n in dir(abysslight) if not n.startswith("_")} | {"__version__"}
    assert public == set(abysslight.__all__), public ^ set(abysslight.__all__)
    for name in ("Any", "Callable", "Dict", "Optional"):
        assert not hasattr(abysslight, name), name
    for name in abysslight.__all__:
        assert hasattr(abysslight, name), name


def _swinging_dive():
    dive = abysslight.simulate(frames=14, water_column=4, width=96, height=64, seed=7)
    altitudes = [3.0 + 1.2 * np.sin(i / 2.0) for i in range(14)]
    return dive, altitudes


def test_altitudes_none_is_not_in_the_log_and_true_is_refused():
    dive, altitudes = _swinging_dive()
    photos, water = dive["survey"], dive["water_column"]
    scatter = abysslight.Scatter.from_frames(water)
    # No altitude at all, said with None: the windows over time, the pixels of a call without altitudes.
    plain = abysslight.correct_arrays(photos, water_column=scatter)
    nones = abysslight.correct_arrays(photos, water_column=scatter, altitudes=[None] * len(photos))
    assert all(np.array_equal(a, b) for a, b in zip(plain, nones))
    # A log that starts at the fourth photo: the same as an engine told to expect altitudes from the first photo.
    late = [None, None, None, *altitudes[3:]]
    arrays = abysslight.correct_arrays(photos, water_column=scatter, altitudes=late)
    engine = abysslight.Engine(scatter=scatter, by_altitude=True)
    got = {}
    for i, (p, a) in enumerate(zip(photos, late)):
        for c in engine.push(p, i, altitude=a):
            got[c.tag] = c
    for c in engine.finish():
        got[c.tag] = c
    assert all(np.array_equal(arrays[i], got[i].image) for i in range(len(photos)))
    assert [got[i].altitude for i in range(len(photos))] == pytest.approx(late)
    # True would read as 1 m: refused, in a list and in push.
    with pytest.raises(TypeError, match="number of metres"):
        abysslight.correct_arrays(photos[:3], altitudes=[True, 3.0, 3.1])
    with pytest.raises(TypeError, match="number of metres"):
        abysslight.Engine().push(photos[0], 0, altitude=True)
    with pytest.raises(TypeError, match="list of numbers"):
        abysslight.correct_arrays(photos[:3], altitudes="3.0")


def test_altitudes_that_start_after_the_first_photo_are_not_ignored_silently():
    dive, altitudes = _swinging_dive()
    engine = abysslight.Engine()
    engine.push(dive["survey"][0], 0)
    with pytest.raises(ValueError, match="by_altitude=True"):
        engine.push(dive["survey"][1], 1, altitude=altitudes[1])
    # The refused push left the engine as it was: the photo can be pushed again without its altitude.
    engine.push(dive["survey"][1], 1)
    assert engine.waiting == 2
