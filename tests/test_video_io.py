"""Real video files: lossless round trip, H.264 reading, region conversion, clear errors."""
import numpy as np
import pytest

from panto.video_sync.video_io import (VideoError, VideoWriter, read_frame_views, read_frames,
                                 video_info)

WIDTH, HEIGHT = 160, 96


def _frames(count, seed=0, noise=20.0):
    rng = np.random.default_rng(seed)
    rows, columns = np.mgrid[0:HEIGHT, 0:WIDTH]
    base = np.stack([100 + 60 * np.sin(columns / 9.0), 120 + 50 * np.cos(rows / 7.0),
                     np.full((HEIGHT, WIDTH), 90.0)], axis=-1)
    return [np.clip(base + rng.normal(0, noise, base.shape), 0, 255).astype(np.uint8)
            for _ in range(count)]


def test_lossless_round_trips_rgb_exactly(tmp_path):
    frames = _frames(12)
    path = tmp_path / "clip.mkv"
    with VideoWriter(path, WIDTH, HEIGHT, 50.0, codec="lossless") as writer:
        for frame in frames:
            writer.write(frame)
    read = list(read_frames(path))
    assert [f.index for f in read] == list(range(12))
    np.testing.assert_allclose([f.time for f in read], np.arange(12) / 50.0, atol=1e-9)
    for original, decoded in zip(frames, read):
        np.testing.assert_array_equal(decoded.rgb, original)
    info = video_info(path)
    assert (info.width, info.height, info.fps) == (WIDTH, HEIGHT, 50.0)
    # the region path (planes, no full conversion) gives the same pixels
    for original, view in zip(frames, read_frame_views(path)):
        np.testing.assert_array_equal(view.crop(30, 20, 90, 70), original[20:70, 30:90])


@pytest.mark.parametrize("codec", ["h264", "h264-420"])
def test_h264_region_conversion_matches_ffmpeg(tmp_path, codec):
    """Our BT.601 conversion of a region equals FFmpeg's whole-frame conversion (+-1 level)."""
    frames = _frames(6, seed=1, noise=3.0)
    path = tmp_path / f"clip-{codec}.mp4"
    with VideoWriter(path, WIDTH, HEIGHT, 50.0, codec=codec, crf=12) as writer:
        for frame in frames:
            writer.write(frame)
    assert video_info(path).pixel_format == ("yuv444p" if codec == "h264" else "yuv420p")
    for original, view in zip(frames, read_frame_views(path)):
        region = view.crop(17, 11, 101, 83).astype(int)
        whole = view.rgb()[11:83, 17:101].astype(int)
        assert np.abs(region - whole).max() <= 1
        assert np.abs(whole - original[11:83, 17:101]).mean() < 4  # it is the same picture


def test_missing_corrupt_and_non_video_files_give_clear_errors(tmp_path):
    with pytest.raises(VideoError, match="nothing.mp4.*not found"):
        list(read_frames(tmp_path / "nothing.mp4"))
    text = tmp_path / "notes.mp4"
    text.write_text("this is not a video\n" * 50)
    with pytest.raises(VideoError, match="notes.mp4"):
        list(read_frames(text))
    with pytest.raises(VideoError, match="notes.mp4"):
        video_info(text)
    good = tmp_path / "good.mkv"
    with VideoWriter(good, WIDTH, HEIGHT, codec="lossless") as writer:
        for frame in _frames(5):
            writer.write(frame)
    data = bytearray(good.read_bytes())
    rng = np.random.default_rng(0)
    garbled = tmp_path / "garbled.mkv"
    data[200:] = rng.integers(0, 256, len(data) - 200, dtype=np.uint8).tobytes()
    garbled.write_bytes(bytes(data))
    with pytest.raises(VideoError, match="garbled.mkv"):
        list(read_frames(garbled))


def test_writer_refuses_a_wrong_frame(tmp_path):
    with VideoWriter(tmp_path / "x.mp4", WIDTH, HEIGHT) as writer:
        with pytest.raises(ValueError, match="frame 0 must be uint8"):
            writer.write(np.zeros((HEIGHT, WIDTH), np.uint8))
        writer.write(_frames(1)[0])
