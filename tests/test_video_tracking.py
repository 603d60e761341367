"""Marker tracking and LED read-out on videos of the synthetic camera, whose truth is known."""
import json
import math
from dataclasses import replace

import numpy as np
import pytest
from scipy import ndimage

from fixtures.video_truth import marker_truth, pixel_errors
from panto.video_sync.camera import CameraSetup, ShadowEvent, render_run
from panto.video_sync.plots import plot_detection_steps
from panto.video_sync.setup import make_setup, setup_from_camera
from panto.video_sync.tracking import (SetupError, TrackerSetup, TrackResult, disk_footprint,
                                 isodata_threshold, track_video)

SHADOW = ShadowEvent("cross_bar", first_frame=30, frame_count=12)


def _small_camera():
    return replace(CameraSetup().reduced(1 / 3), shadow=SHADOW)


@pytest.fixture(scope="module")
def lossless(tmp_path_factory):
    folder = tmp_path_factory.mktemp("lossless")
    truth = marker_truth(2.0)
    truth.write(folder / "truth.csv")  # render from a run folder, as the CLI does
    result = render_run(folder, folder / "video.mkv", setup=_small_camera(), codec="lossless",
                        rng=3)
    return truth, result, track_video(result.path, setup_from_camera(result.camera_json))


@pytest.fixture(scope="module")
def h264_full_hd(tmp_path_factory):
    folder = tmp_path_factory.mktemp("h264")
    camera = replace(CameraSetup(), shadow=replace(SHADOW, first_frame=10, frame_count=5))
    result = render_run(marker_truth(1.0, seed=1), folder / "video.mp4", setup=camera, codec="h264",
                        rng=5, duration=0.6)
    return result, track_video(result.path, setup_from_camera(result.camera_json))


def test_disk_footprint_is_the_defined_shape():
    footprint = disk_footprint(2)
    expected = np.array([[0, 0, 1, 0, 0],
                         [0, 1, 1, 1, 0],
                         [1, 1, 1, 1, 1],
                         [0, 1, 1, 1, 0],
                         [0, 0, 1, 0, 0]], dtype=bool)
    np.testing.assert_array_equal(footprint, expected)
    assert footprint.sum() == 13
    # OpenCV's getStructuringElement(MORPH_ELLIPSE, (5, 5)) is another shape (21 pixels).
    opencv_ellipse = np.array([[0, 0, 1, 0, 0]] + [[1] * 5] * 3 + [[0, 0, 1, 0, 0]], dtype=bool)
    assert not np.array_equal(footprint, opencv_ellipse)
    for radius in range(5):  # the definition i^2 + j^2 <= r^2, counted independently
        count = sum(1 for i in range(-radius, radius + 1) for j in range(-radius, radius + 1)
                    if i * i + j * j <= radius * radius)
        assert disk_footprint(radius).sum() == count


def test_opening_removes_a_speck_and_keeps_a_marker():
    rows, columns = np.mgrid[0:40, 0:60]
    marker = (columns - 35.3) ** 2 + (rows - 20.6) ** 2 <= 6.0 ** 2
    image = marker.copy()
    image[5, 5:7] = True  # a 2-pixel speck
    image[30:32, 10:12] = True  # a 2 x 2 speck
    opened = ndimage.binary_opening(image, structure=disk_footprint(2))
    assert not opened[:, :20].any()
    assert opened.sum() >= 0.9 * marker.sum() and not (opened & ~marker).any()
    # The opened blob's centroid stays within a quarter pixel (opening trims a digital disc's
    # boundary unevenly: why the tracker's sub-pixel centre uses coverage weights instead).
    kept = np.argwhere(opened).mean(axis=0)
    np.testing.assert_allclose(kept, np.argwhere(marker).mean(axis=0), atol=0.25)


def test_isodata_threshold_splits_two_clusters_half_way():
    values = np.concatenate([np.full(90, 0.2), np.full(10, 0.9)])
    assert isodata_threshold(values) == pytest.approx(0.55)


def test_lossless_centroids_are_sub_pixel_true(lossless):
    _, result, track = lossless
    for name in track.markers:
        errors = pixel_errors(result, track, name)
        assert errors.size > 0.8 * result.frame_count
        assert errors.mean() < 0.15, name


def test_h264_444_centroids_within_half_a_pixel(h264_full_hd):
    result, track = h264_full_hd
    for name in track.markers:
        assert pixel_errors(result, track, name).mean() < 0.5, name
    assert np.array_equal(track.led, result.led)


def test_metres_agree_with_the_test_bed_truth(lossless):
    truth, result, track = lossless
    samples = result.start_sample + 10 * np.arange(result.frame_count)
    scale = 1e-3 * CameraSetup().reduced(1 / 3).marker("pan_head").mm_per_px[1]
    for name, channel in (("pan_head", "xi"), ("cross_bar", "y_cb"), ("slider", "eta")):
        marker = track.markers[name]
        error = marker.y[marker.valid] - truth[channel][samples][marker.valid]
        assert np.mean(np.abs(error)) < 0.15 * scale * 1.1, name
        error_x = marker.x[marker.valid] - truth["x_cb"][samples][marker.valid]
        assert np.mean(np.abs(error_x)) < 0.15 * scale * 1.1, name


def test_shadowed_frames_are_flagged_not_invented(lossless, h264_full_hd):
    for result, track in (lossless[1:], h264_full_hd):
        for name, marker in track.markers.items():
            np.testing.assert_array_equal(marker.valid, result.visible[name])
            assert np.all(np.isnan(marker.x_px[~marker.valid]))
            assert np.all(np.isnan(marker.y[~marker.valid]))
        shadow = result.visible["cross_bar"]
        assert track.lost_frames["cross_bar"] == np.count_nonzero(~shadow) > 0
        assert track.lost_frames["pan_head"] == 0


def test_a_marker_leaving_its_region_is_lost_not_clamped(lossless):
    _, result, _ = lossless
    setup = setup_from_camera(result.camera_json)
    pan_head = setup.marker("pan_head")
    true_rows = result.pixels["pan_head"][:, 1]
    cut = float(np.median(true_rows))  # the region ends half way through the motion
    roi = (pan_head.roi[0], pan_head.roi[1], pan_head.roi[2], int(cut))
    narrowed = TrackerSetup(tuple(replace(m, roi=roi) if m.name == "pan_head" else m
                                  for m in setup.markers), setup.led)
    marker = track_video(result.path, narrowed).markers["pan_head"]
    radius = pan_head.radius_px
    inside = true_rows + radius + 1 < cut
    outside = true_rows - radius > cut
    assert inside.any() and outside.any()
    assert not marker.valid[outside].any()
    assert marker.valid[inside].mean() > 0.9  # re-acquired after every excursion
    error = np.hypot(marker.x_px - result.pixels["pan_head"][:, 0],
                     marker.y_px - result.pixels["pan_head"][:, 1])
    assert np.nanmax(error) < 0.5


def test_led_bits_read_back_exactly(lossless):
    _, result, track = lossless
    assert 0 < result.led.mean() < 1
    np.testing.assert_array_equal(track.led, result.led)
    assert track.led_separation > 0.8
    assert track.led_quality.min() > 0.5


def test_track_file_round_trips_with_the_agreed_columns(lossless, tmp_path):
    _, _, track = lossless
    path = track.to_csv(tmp_path / "track.csv")
    header = path.read_text().splitlines()[0].split(",")
    names = list(track.markers)
    expected = ["frame", "time"] + [f"{m}_{c}" for m in names
                                    for c in ("x_px", "y_px", "x", "y", "valid")]
    assert header == expected + ["led", "led_quality"]
    side = json.loads((tmp_path / "track.csv.json").read_text())
    assert side["format"] == "panto-video-track" and side["version"] == 1
    assert side["fps"] == 50.0 and side["markers"] == names
    assert side["lost_frames"] == track.lost_frames
    back = TrackResult.from_csv(path)
    assert back.setup == track.setup
    np.testing.assert_array_equal(back.frame, track.frame)
    np.testing.assert_array_equal(back.time, track.time)
    for name in names:
        np.testing.assert_array_equal(back.markers[name].y, track.markers[name].y)
        np.testing.assert_array_equal(back.markers[name].valid, track.markers[name].valid)
    np.testing.assert_array_equal(back.led, track.led)


def test_setup_routine_from_clicks_finds_colour_radius_and_threshold(lossless, tmp_path):
    _, result, track_camera = lossless
    camera = CameraSetup().reduced(1 / 3)
    clicks = {name: (result.pixels[name][0, 0] + 1.5, result.pixels[name][0, 1] - 1.0)
              for name in ("pan_head", "cross_bar", "slider")}
    led = camera.led.centre_px
    setup = make_setup(result.path, clicks, led=(led[0] + 1, led[1]),
                       mm_per_px={m: camera.marker(m).mm_per_px for m in clicks},
                       roi_half_size=(40, 120))
    for marker in setup.markers:
        drawn = camera.marker(marker.name)
        assert marker.radius_px == pytest.approx(drawn.radius_px, abs=1.0)
        assert np.linalg.norm(np.subtract(marker.colour, drawn.colour)) < 40  # lighting drifts
        assert 0.6 < marker.threshold < 0.97
    saved = TrackerSetup.load(setup.save(tmp_path / "setup.json"))
    assert saved == setup
    track = track_video(result.path, saved)
    for name in clicks:
        assert pixel_errors(result, track, name).mean() < 0.15, name
    np.testing.assert_array_equal(track.led, result.led)
    picture = plot_detection_steps(result.path, saved, 5, tmp_path / "steps.png")
    assert picture.stat().st_size > 10_000


def test_setup_file_with_a_missing_field_is_refused_by_name(lossless, tmp_path):
    setup = setup_from_camera(lossless[1].camera_json)
    data = setup.to_dict()
    del data["markers"][1]["threshold"]
    path = tmp_path / "broken.json"
    path.write_text(json.dumps(data))
    with pytest.raises(SetupError, match=r"broken\.json.*markers\[1\].*threshold"):
        TrackerSetup.load(path)
    path.write_text("{not json")
    with pytest.raises(SetupError, match="broken.json"):
        TrackerSetup.load(path)
    data = setup.to_dict()
    data["markers"][0]["roi"] = [1, 2, 3]
    path.write_text(json.dumps(data))
    with pytest.raises(SetupError, match="roi"):
        TrackerSetup.load(path)


def test_camera_side_file_keeps_the_start_as_labelled_truth(lossless):
    _, result, _ = lossless
    side = json.loads(result.camera_json.read_text())
    assert side["truth_for_tests_only"]["start_sample"] == result.start_sample
    assert side["truth_for_tests_only"]["shadow_frames"] == {
        "cross_bar": [SHADOW.first_frame, SHADOW.first_frame + SHADOW.frame_count - 1]}
    assert side["frame_count"] == result.frame_count
    # frame k shows sample start + 10 k: the rendered LED is the truth's LED there
    truth = lossless[0]
    samples = result.start_sample + 10 * np.arange(result.frame_count)
    np.testing.assert_array_equal(result.led, truth["led"][samples].astype(int))
    assert math.isclose(result.start_time, truth.time[result.start_sample])


def test_cli_renders_sets_up_and_tracks(tmp_path, capsys):
    from panto.cli import main

    marker_truth(1.5, seed=2).write(tmp_path / "truth.csv")
    video = tmp_path / "camera.mp4"
    assert main(["video", "render", str(tmp_path), "--out", str(video), "--duration", "0.8",
                 "--scale", "0.3333", "--seed", "4"]) == 0
    assert main(["video", "setup", str(video), "--camera", f"{video}.json",
                 "--out", str(tmp_path / "setup.json"), "--picture",
                 str(tmp_path / "steps.png")]) == 0
    assert main(["video", "track", str(video), "--setup", str(tmp_path / "setup.json"),
                 "--out", str(tmp_path / "track.csv"), "--json", str(tmp_path / "s.json")]) == 0
    printed = capsys.readouterr().out
    assert "41 frames" in printed and "cross_bar: 0 lost frames" in printed
    summary = json.loads((tmp_path / "s.json").read_text())
    assert summary["frames"] == 41 and summary["led_quality"] > 0.5
    assert (tmp_path / "steps.png").is_file()
    assert main(["video", "track", str(tmp_path / "truth.csv"), "--setup",
                 str(tmp_path / "setup.json"), "--out", str(tmp_path / "t2.csv")]) == 65
    assert "truth.csv" in capsys.readouterr().err


@pytest.fixture(scope="module")
def short_gops(lossless, tmp_path_factory):
    """The lossless clip re-encoded as H.264 4:4:4 (B-frames) with a keyframe every 10 frames."""
    from panto.video_sync.video_io import VideoWriter, read_frames

    _, result, _ = lossless
    path = tmp_path_factory.mktemp("gops") / "short-gops.mp4"
    camera = result.camera_json
    frames = list(read_frames(result.path))
    height, width = frames[0].rgb.shape[:2]
    with VideoWriter(path, width, height, 50.0, codec="h264", keyframe_interval=0.2) as writer:
        for frame in frames:
            writer.write(frame.rgb)
    return path, setup_from_camera(camera), result


def test_writer_places_keyframes_at_the_interval(lossless, short_gops):
    from panto.video_sync.video_io import split_at_keyframes, video_info

    path, _, result = short_gops
    segments = split_at_keyframes(path, 1000)  # more parts than groups: one segment per group
    assert [s.start_index for s in segments] == list(range(0, result.frame_count, 10))
    assert sum(s.frame_count for s in segments) == result.frame_count
    assert video_info(path).frame_count == result.frame_count
    # the camera's default: a keyframe every second (50 frames)
    starts = [s.start_index for s in split_at_keyframes(lossless[1].path, 1000)]
    assert starts == list(range(0, lossless[1].frame_count, 50))
    halves = split_at_keyframes(path, 2)  # cut at the keyframe nearest half way
    middle = min(range(0, result.frame_count, 10), key=lambda k: abs(k - result.frame_count / 2))
    assert [s.start_index for s in halves] == [0, middle]
    assert [s.frame_count for s in halves] == [middle, result.frame_count - middle]


def test_a_segment_decodes_the_same_pixels_as_the_whole_file(short_gops):
    from panto.video_sync.video_io import read_frame_views, split_at_keyframes

    path, _, _ = short_gops
    whole = [(v.index, v.time, v.crop(0, 0, 64, 48)) for v in read_frame_views(path)]
    for segment in split_at_keyframes(path, 4)[1:]:
        part = [(v.index, v.time, v.crop(0, 0, 64, 48))
                for v in read_frame_views(path, segment=segment)]
        assert [p[0] for p in part] == list(range(segment.start_index,
                                                  segment.start_index + segment.frame_count))
        for (index, time, pixels), (index_, time_, pixels_) in zip(part, whole[part[0][0]:]):
            assert (index, time) == (index_, time_)
            np.testing.assert_array_equal(pixels, pixels_)


def _assert_same_tracks(parallel, serial):
    np.testing.assert_array_equal(parallel.frame, serial.frame)
    np.testing.assert_array_equal(parallel.time, serial.time)
    for name, track in serial.markers.items():
        np.testing.assert_array_equal(parallel.markers[name].valid, track.valid)
        np.testing.assert_allclose(parallel.markers[name].x_px, track.x_px, rtol=0, atol=1e-9)
        np.testing.assert_allclose(parallel.markers[name].y_px, track.y_px, rtol=0, atol=1e-9)
    np.testing.assert_array_equal(parallel.led, serial.led)
    np.testing.assert_array_equal(parallel.led_level, serial.led_level)


def test_parallel_segments_track_exactly_as_one_serial_pass(short_gops):
    from concurrent.futures import ThreadPoolExecutor

    path, setup, result = short_gops
    serial = track_video(path, setup, workers=1)
    # the shadow (frames 30 .. 41) covers segment starts 30 and 40: a segment may start lost
    assert serial.lost_frames["cross_bar"] == np.count_nonzero(~result.visible["cross_bar"]) > 0
    for name in serial.markers:
        assert pixel_errors(result, serial, name).mean() < 0.5, name
    lines = []
    parallel = track_video(path, setup, workers=2, progress=lines.append)  # local process pool
    segments = -(-result.frame_count // 10)  # one per group of pictures (at most 4 per worker)
    assert len(lines) == min(segments, 8)
    assert lines[-1].startswith(f"tracked {result.frame_count}/{result.frame_count} frames")
    _assert_same_tracks(parallel, serial)
    with ThreadPoolExecutor(2) as executor:  # any executor will do
        _assert_same_tracks(track_video(path, setup, workers=3, executor=executor), serial)
    with pytest.raises(ValueError, match="workers = 0"):
        track_video(path, setup, workers=0)
