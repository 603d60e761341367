"""Video synchronisation (thesis section 3.2) and merging camera tracks into the 500 Hz run."""
from __future__ import annotations

import json

import numpy as np
import pytest

from panto.rig.dataset import Dataset, RunMetadata, read_dataset
from panto.rig.sync_led import generate_led_bits
from panto.video_sync.merge import MergeOptions, TrackError, read_track, sync_and_merge
from panto.video_sync.plots import plot_synchronisation
from panto.video_sync.synchronisation import SyncError, synchronise

RATE, FPS, DECIMATION = 500.0, 50.0, 10
MARKERS = ("pan_head", "cross_bar", "slider", "reference")


# --- synchronisation -------------------------------------------------------------------------


def _trial(rng: np.random.Generator, *, camera_seconds: float, flip: float):
    """A fine LED record and a camera sequence of the same LED (frame k = fine shift + 10 k)."""
    record = int((camera_seconds + rng.uniform(5.0, 30.0)) * RATE)
    frames = int(camera_seconds * FPS)
    margin = 4000  # fine samples the camera may see before or after the record
    master = generate_led_bits(margin + record + DECIMATION * frames + margin,
                               np.random.default_rng(int(rng.integers(2**31))))
    shift = int(rng.integers(-margin, record - DECIMATION * frames + margin))
    camera = master[margin + shift + DECIMATION * np.arange(frames)].astype(float)
    flipped = rng.random(frames) < flip
    camera[flipped] = 1.0 - camera[flipped]
    return camera, master[margin:margin + record], shift


def test_synchronisation_recovers_the_exact_fine_shift_with_10_percent_bit_errors():
    rng = np.random.default_rng(20240611)
    exact, negative = 0, 0
    trials = 200
    for _ in range(trials):
        camera, fine, shift = _trial(rng, camera_seconds=rng.uniform(30.0, 60.0), flip=0.10)
        result = synchronise(camera, fine)
        exact += result.shift == shift
        negative += shift < 0
        assert result.shift == result.lag * DECIMATION + result.phase
        assert 0 <= result.phase < DECIMATION
        assert 0.7 < result.confidence < 0.9  # 1 - 2 * 10 % flipped = 0.8
    assert exact >= 0.99 * trials
    assert negative >= 10  # the camera started before the recording in some trials


def test_the_peak_per_phase_singles_out_the_true_phase():
    camera, fine, shift = _trial(np.random.default_rng(5), camera_seconds=40.0, flip=0.10)
    result = synchronise(camera, fine)
    peaks = result.peaks_per_phase()
    assert int(np.argmax(peaks)) == shift % DECIMATION
    # adjacent phases are close (long holds) but lower; the correlation at the opposite phase
    # (half a frame away) is clearly lower still
    assert peaks[(shift + 1) % 10] < peaks[shift % 10]
    assert peaks[(shift + 5) % 10] < peaks[(shift + 1) % 10]


def test_synchronisation_refuses_unrelated_sequences():
    for seed in range(20):
        fine = generate_led_bits(30_000, np.random.default_rng(100 + seed))
        camera = generate_led_bits(20_000, np.random.default_rng(900 + seed))[::10]
        with pytest.raises(SyncError, match="confidence|unique"):
            synchronise(camera, fine)


def test_synchronisation_refuses_too_short_overlaps():
    camera, fine, _ = _trial(np.random.default_rng(3), camera_seconds=4.0, flip=0.0)
    with pytest.raises(SyncError, match="too short"):
        synchronise(camera, fine)  # 200 frames < 250
    fine = generate_led_bits(2000, np.random.default_rng(4))  # 4 s of record
    camera = generate_led_bits(6000, np.random.default_rng(4))[::10]
    with pytest.raises(SyncError, match="overlap too short"):
        synchronise(camera, fine)


def test_synchronisation_refuses_non_bits_and_accepts_unknown_camera_frames():
    camera, fine, shift = _trial(np.random.default_rng(8), camera_seconds=30.0, flip=0.05)
    with pytest.raises(SyncError, match="not a bit"):
        synchronise(np.where(camera > 0, 0.5, 0.0), fine)
    camera[::7] = np.nan  # frames whose LED could not be read
    assert synchronise(camera, fine).shift == shift


def test_synchronisation_plot(tmp_path):
    camera, fine, _ = _trial(np.random.default_rng(9), camera_seconds=30.0, flip=0.1)
    path = plot_synchronisation(synchronise(camera, fine), str(tmp_path / "sync.png"))
    assert (tmp_path / "sync.png").stat().st_size > 10_000 and path.endswith("sync.png")


# --- synthetic run + truth + track -----------------------------------------------------------


def _marker_paths(time: np.ndarray) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """True marker positions [m]: smooth motions below 5 Hz, like the pantograph's."""
    x = 0.10 + 0.002 * np.sin(2 * np.pi * 0.7 * time)
    y_cb = 2.0 + 0.03 * np.sin(2 * np.pi * 1.0 * time) + 0.004 * np.sin(2 * np.pi * 3.1 * time)
    return {"pan_head": (x, y_cb + 0.05 + 0.003 * np.sin(2 * np.pi * 4.2 * time + 1.0)),
            "cross_bar": (x, y_cb), "slider": (x, 1.95 + 0.03 * np.sin(2 * np.pi * time)),
            "reference": (np.full_like(time, 0.5), np.full_like(time, 1.0))}


def _write_run_and_truth(folder, seed: int, seconds: float):
    """A run folder as the virtual test bed writes it: ``run.csv`` (LED command recorded at
    sample n) and ``truth.csv`` (the LED lights from sample n + 1; true marker positions)."""
    rng = np.random.default_rng(seed)
    n = int(seconds * RATE)
    time = np.arange(-10, n) / RATE  # truth starts before the run, as the test bed's
    command = generate_led_bits(time.size, rng).astype(float)
    shown = np.concatenate([[0.0], command[:-1]])  # the LED one sample after the command
    paths = _marker_paths(time)
    folder.mkdir()
    truth = {"led": shown, "x_cb": paths["cross_bar"][0], "y_cb": paths["cross_bar"][1],
             "xi": paths["pan_head"][1], "eta": paths["slider"][1]}
    Dataset(time, truth, {k: ("1" if k == "led" else "m") for k in truth},
            RunMetadata(sample_rate=RATE, source="emulator")).write(folder / "truth.csv")
    run = time >= 0
    channels = {name: rng.normal(0.0, 1.0, n) for name in
                ("motor_demand", "motor_command", "motor_position", "pressure_demand")}
    channels.update(force=80 + rng.normal(0.0, 1.0, n), pressure=4 + rng.normal(0, 0.01, n),
                    led=command[run])
    Dataset(time[run], channels, {"force": "N", "pressure": "bar", "pressure_demand": "bar"},
            RunMetadata(sample_rate=RATE, source="emulator")).write(folder / "run.csv")


def _write_track(path, truth: Dataset, *, start: int, frames: int, noise: float, flip: float,
                 lost: dict[str, slice], seed: int) -> None:
    """A track file as the tracker writes it, from the truth seen at truth rows start + 10 k."""
    rng = np.random.default_rng(seed)
    rows = start + DECIMATION * np.arange(frames)
    paths = {"pan_head": (truth["x_cb"], truth["xi"]), "cross_bar": (truth["x_cb"], truth["y_cb"]),
             "slider": (truth["x_cb"], truth["eta"]),
             "reference": (np.full(len(truth), 0.5), np.full(len(truth), 1.0))}
    led = truth["led"][rows].copy()
    flipped = rng.random(frames) < flip
    led[flipped] = 1 - led[flipped]
    columns = {"frame": np.arange(frames), "time": np.arange(frames) / FPS}
    lost_frames = {}
    for marker in MARKERS:
        valid = np.ones(frames, dtype=bool)
        valid[lost.get(marker, slice(0, 0))] = False
        lost_frames[marker] = int((~valid).sum())
        for axis, values in zip(("x", "y"), paths[marker]):
            metres = values[rows] + rng.normal(0.0, noise, frames)
            columns[f"{marker}_{axis}_px"] = np.where(valid, metres / 5e-4, np.nan)
            columns[f"{marker}_{axis}"] = np.where(valid, metres, np.nan)
        columns[f"{marker}_valid"] = valid.astype(int)
    columns["led"] = led.astype(int)
    columns["led_quality"] = np.full(frames, 0.9)
    import pandas as pd

    pd.DataFrame(columns).to_csv(path, index=False)
    side = {"format": "panto-video-track", "version": 1, "video": "synthetic.mkv", "fps": FPS,
            "markers": list(MARKERS), "setup": {}, "lost_frames": lost_frames}
    path.with_name(path.name + ".json").write_text(json.dumps(side))


@pytest.fixture
def synthetic(tmp_path):
    folder = tmp_path / "run"
    _write_run_and_truth(folder, seed=11, seconds=40.0)
    truth = read_dataset(folder / "truth.csv", required=())
    track = tmp_path / "track.csv"
    # camera from truth row 2003 (run sample 1993), 30 s, pan-head lost for 1 s
    _write_track(track, truth, start=2003, frames=1500, noise=5e-5, flip=0.1,
                 lost={"pan_head": slice(600, 650)}, seed=12)
    return folder, track, truth


def test_merged_dataset_passes_the_schema_and_agrees_with_the_truth(synthetic, tmp_path):
    folder, track, truth = synthetic
    result = sync_and_merge(folder, track, tmp_path / "merged")
    merged = read_dataset(result.path)  # the schema check of every reader
    run = read_dataset(folder)
    info = merged.metadata.extra["video_sync"]
    # camera frame 0 shows truth row 2003, whose LED is the command of run sample 2003 - 10 - 1
    assert result.sync.shift == 2003 - 10 - 1 and info["shift_samples"] == result.sync.shift
    assert info["phase"] == result.sync.shift % 10 and info["interpolation"] == "cubic"
    assert merged.time[0] == pytest.approx(truth.time[2003])
    assert len(merged) == 10 * (1500 - 1) + 1 and result.frames_merged == 1500
    assert np.array_equal(merged["force"], run["force"][1993:1993 + len(merged)])
    rows = np.searchsorted(truth.time, merged.time - 1e-9)
    assert np.allclose(truth.time[rows], merged.time)
    for marker, column in (("pan_head", "xi"), ("cross_bar", "y_cb"), ("slider", "eta")):
        y, valid = merged[f"video_{marker}_y"], merged[f"video_{marker}_valid"] == 1
        error = y[valid] - truth[column][rows][valid]
        assert np.sqrt(np.mean(error ** 2)) < 6e-5  # about the tracking noise (50 um)
        assert np.max(np.abs(error)) < 4e-4
        assert np.all(np.isnan(y[~valid]))
        x_error = merged[f"video_{marker}_x"][valid] - truth["x_cb"][rows][valid]
        assert np.sqrt(np.mean(x_error ** 2)) < 6e-5
    gap = merged["video_pan_head_valid"] == 0
    # frames 600..649 lost: samples strictly between frames 599 and 650 are gaps
    assert gap.sum() == 10 * 51 - 1 == result.gap_samples["pan_head"]
    assert np.all(gap[10 * 599 + 1:10 * 650]) and not gap[10 * 599] and not gap[10 * 650]
    assert result.gap_samples["slider"] == 0 and "video_reference_y" not in merged.channels


def test_cubic_upsampling_beats_linear_on_noise_free_tracks(tmp_path):
    folder = tmp_path / "run"
    _write_run_and_truth(folder, seed=21, seconds=30.0)
    truth = read_dataset(folder / "truth.csv", required=())
    track = tmp_path / "track.csv"
    _write_track(track, truth, start=1507, frames=1200, noise=0.0, flip=0.05, lost={}, seed=1)
    errors = {}
    for method in ("cubic", "linear"):
        merged = sync_and_merge(folder, track, tmp_path / method,
                                options=MergeOptions(interpolation=method)).dataset
        rows = np.searchsorted(truth.time, merged.time - 1e-9)
        inner = slice(100, -100)  # the not-a-knot ends are less accurate
        errors[method] = np.max(np.abs(merged["video_pan_head_y"] - truth["xi"][rows])[inner])
    # frames 20 ms apart; error bounds: cubic spline 5 h^4 max|y''''| / 384 (Hall 1968), linear
    # h^2 max|y''| / 8
    h, amplitudes = 0.02, [(0.03, 1.0), (0.004, 3.1), (0.003, 4.2)]
    linear_bound = sum(a * (2 * np.pi * f) ** 2 for a, f in amplitudes) * h ** 2 / 8
    cubic_bound = 5 * sum(a * (2 * np.pi * f) ** 4 for a, f in amplitudes) * h ** 4 / 384
    assert errors["linear"] <= linear_bound * 1.01
    assert errors["cubic"] <= cubic_bound
    assert errors["cubic"] < errors["linear"] / 20


def test_camera_starting_before_the_recording_is_cropped(tmp_path):
    folder = tmp_path / "run"
    _write_run_and_truth(folder, seed=31, seconds=30.0)
    truth = read_dataset(folder / "truth.csv", required=())
    # truth row 3 is before the run (row 10 is t = 0): frame 0 sees the run's sample -7
    track = tmp_path / "track.csv"
    _write_track(track, truth, start=3, frames=900, noise=0.0, flip=0.1, lost={}, seed=2)
    result = sync_and_merge(folder, track, tmp_path / "merged")
    assert result.sync.shift == 3 - 10 - 1 and result.sync.lag == -1 and result.sync.phase == 2
    # frame 0 falls at run sample -7: the merge starts at sample 0, interpolated from frames
    # 0 and 1 (frame 1 is at run sample 3)
    assert result.dataset.time[0] == 0.0 and result.frames_merged == 899
    assert result.dataset["video_slider_valid"].all()
    error = result.dataset["video_slider_y"][:4] - truth["eta"][10:14]
    assert np.max(np.abs(error)) < 1e-5


def test_a_refused_synchronisation_writes_nothing(tmp_path):
    folder = tmp_path / "run"
    _write_run_and_truth(folder, seed=41, seconds=20.0)
    other = tmp_path / "other"
    _write_run_and_truth(other, seed=42, seconds=20.0)
    track = tmp_path / "track.csv"
    _write_track(track, read_dataset(other / "truth.csv", required=()), start=500, frames=800,
                 noise=0.0, flip=0.0, lost={}, seed=3)
    with pytest.raises(SyncError, match="confidence|unique"):
        sync_and_merge(folder, track, tmp_path / "merged")
    assert not (tmp_path / "merged").exists()


def test_read_track_names_file_column_and_row(synthetic, tmp_path):
    _, track, _ = synthetic
    good = read_track(track)
    assert good.fps == FPS and good.markers == MARKERS and good.frames.size == 1500
    assert np.isnan(good.positions["pan_head"][1][600]) and not good.valid["pan_head"][600]
    text = track.read_text().splitlines()
    header = text[0].split(",")
    broken = tmp_path / "broken.csv"
    row = text[5].split(",")
    row[header.index("led")] = "2"
    broken.write_text("\n".join([text[0], *text[1:5], ",".join(row), *text[6:]]) + "\n")
    broken.with_name("broken.csv.json").write_text(track.with_name("track.csv.json").read_text())
    with pytest.raises(TrackError, match=r"broken.csv: column 'led', row 5: 2.0 is not 0/1"):
        read_track(broken)
    missing = tmp_path / "missing.csv"
    keep = [i for i, h in enumerate(header) if h != "slider_y"]
    missing.write_text("\n".join(",".join(line.split(",")[i] for i in keep) for line in text))
    missing.with_name("missing.csv.json").write_text(track.with_name("track.csv.json").read_text())
    with pytest.raises(TrackError, match="column 'slider_y' is missing"):
        read_track(missing)
    (tmp_path / "missing.csv.json").write_text('{"format": "something-else"}')
    with pytest.raises(TrackError, match="not a 'panto-video-track' side file"):
        read_track(missing)


def test_panto_sync_merges_and_a_refusal_exits_non_zero_writing_nothing(synthetic, tmp_path,
                                                                         capsys):
    from panto.cli import main

    folder, track, _ = synthetic
    out, summary, picture = tmp_path / "merged", tmp_path / "sync.json", tmp_path / "sync.png"
    assert main(["sync", str(folder), str(track), "--out", str(out), "--json", str(summary),
                 "--plot", str(picture)]) == 0
    printed = capsys.readouterr().out
    assert "shift 1992 fine samples" in printed and "phase 2" in printed
    assert "frames merged 1500" in printed and "pan_head 509" in printed
    assert json.loads(summary.read_text())["shift_samples"] == 1992
    assert read_dataset(out / "run.csv")["video_slider_y"].size == 14991
    assert picture.stat().st_size > 10_000
    other = tmp_path / "other"
    _write_run_and_truth(other, seed=99, seconds=40.0)
    refused = tmp_path / "refused"
    assert main(["sync", str(other), str(track), "--out", str(refused), "--json",
                 str(tmp_path / "refused.json")]) != 0
    assert "confidence" in capsys.readouterr().err
    assert not refused.exists() and not (tmp_path / "refused.json").exists()


# --- end to end: virtual run -> rendered video -> tracking -> panto sync ---------------------


def test_virtual_run_rendered_tracked_and_merged_agrees_with_the_truth(tmp_path):
    from panto.build_fmu.project import project_fmu
    from panto.rig.profiles import profile_from_dict
    from panto.rig.virtual import run_virtual_profile
    from panto.video_sync.camera import CameraSetup, render_run
    from panto.video_sync.setup import setup_from_camera
    from panto.video_sync.tracking import track_video

    profile = profile_from_dict({
        "name": "video", "duration": 6.0, "seed": 5,
        "limits": {"motor_min": -0.1, "motor_max": 0.1, "safe_pressure": 4.0,
                   "pressure_min": 3.4, "pressure_max": 6.0},
        "motor": {"offset": 0.0,
                  "signals": [{"kind": "sine", "frequency": 1.0, "amplitude": 0.03}]},
        "pressure": {"offset": 4.0, "signals": []}})
    folder = tmp_path / "run"
    run_virtual_profile(profile, fmu_path=project_fmu("Pantograph"), folder=folder, seed=2)
    video = tmp_path / "camera.mkv"
    rendered = render_run(folder, video, setup=CameraSetup().reduced(0.25), codec="lossless",
                          start_sample=437, duration=5.0, rng=3)
    track = track_video(video, setup_from_camera(rendered.camera_json))
    track_csv = tmp_path / "track.csv"
    track.to_csv(track_csv)
    result = sync_and_merge(folder, track_csv, tmp_path / "merged")
    merged = read_dataset(result.path)  # passes the schema check
    truth = read_dataset(folder / "truth.csv", required=())
    run = read_dataset(folder)
    # frame 0 shows truth row 437; the run's sample 0 is truth row `first`
    first = int(np.searchsorted(truth.time, run.time[0] - 1e-9))
    assert result.sync.shift + 1 == 437 - first
    assert merged.time[0] == pytest.approx(truth.time[437])
    rows = np.searchsorted(truth.time, merged.time - 1e-9)
    at_frames = np.zeros(len(merged), dtype=bool)
    at_frames[::10] = True  # frame k at merged row 10 k
    for marker, column in (("pan_head", "xi"), ("cross_bar", "y_cb"), ("slider", "eta")):
        valid = merged[f"video_{marker}_valid"] == 1
        assert valid.mean() > 0.8
        error = merged[f"video_{marker}_y"] - truth[column][rows]
        scale = 1e-3 * CameraSetup().reduced(0.25).marker(marker).mm_per_px[1]  # [m/px]
        rms_all = np.sqrt(np.mean(error[valid] ** 2)) / scale
        rms_frames = np.sqrt(np.mean(error[valid & at_frames] ** 2)) / scale
        # the tracker's error at the frames (480 x 270 px video) ...
        assert rms_frames < 0.3, marker
        # ... and the upsampling between frames adds (almost) nothing to it
        assert rms_all < 1.1 * rms_frames + 0.01, marker
    hidden = ~rendered.visible["cross_bar"]  # the camera's shadow hides it for 20 frames
    assert hidden.sum() >= 10
    frame_rows = 10 * np.arange(rendered.frame_count)  # frame k at merged row 10 k
    assert np.all(merged["video_cross_bar_valid"][frame_rows[hidden]] == 0)  # gaps, not guesses
    assert result.gap_samples["cross_bar"] >= 10 * (hidden.sum() - 1)
