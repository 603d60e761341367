"""Real encoded video files through PyAV (FFmpeg): write, read frame by frame, crop cheaply.

The camera of the thesis (section 3.2) records Full HD at 50 frames per second; a recording is one
video file. Two encodings are offered:

``"h264"``
    libx264 in ``yuv444p`` (full-resolution colour, the marker colours are not blurred by chroma
    subsampling), quality by the constant rate factor `crf`.
``"h264-420"``
    libx264 in ``yuv420p`` (what most consumer cameras deliver; chroma at half resolution).
``"lossless"``
    libx264rgb with ``qp=0``: RGB in, RGB out, bit-exact. FFV1 (``bgr0``) also round-trips RGB
    exactly, but encodes and decodes about ten times slower here, so libx264rgb is the choice.

Reading streams one frame at a time (:func:`read_frames`), so a long recording never has to fit
in memory. The tracker uses :func:`read_frame_views`, whose :class:`FrameView` converts only the
regions it is asked for to RGB: converting a whole 1080p frame costs more than tracking four
markers (see ``benchmarks/video_tracking_speed.py``). The YUV -> RGB conversion of a region is
the inverse of the ITU-R BT.601 limited-range matrix that FFmpeg's swscale uses by default:

.. math::

    R = 1.164 (Y - 16) + 1.596 (V - 128), \\quad
    G = 1.164 (Y - 16) - 0.392 (U - 128) - 0.813 (V - 128), \\quad
    B = 1.164 (Y - 16) + 2.017 (U - 128).
"""
from __future__ import annotations

from dataclasses import dataclass
from fractions import Fraction
from pathlib import Path
from typing import Any, Iterator

import numpy as np

CODECS = ("h264", "h264-420", "lossless")
# codec option -> (FFmpeg encoder, pixel format)
_ENCODERS = {"h264": ("libx264", "yuv444p"), "h264-420": ("libx264", "yuv420p"),
             "lossless": ("libx264rgb", "rgb24")}
# BT.601 limited range, YUV (offset removed) -> RGB
_YUV_TO_RGB = np.array([[1.164383, 0.0, 1.596027],
                        [1.164383, -0.391762, -0.812968],
                        [1.164383, 2.017232, 0.0]], dtype=np.float32)
_YUV_OFFSET = np.array([16.0, 128.0, 128.0], dtype=np.float32)
_YUVJ_OFFSET = np.array([0.0, 128.0, 128.0], dtype=np.float32)
# BT.601 full range (yuvj*)
_YUVJ_TO_RGB = np.array([[1.0, 0.0, 1.402],
                         [1.0, -0.344136, -0.714136],
                         [1.0, 1.772, 0.0]], dtype=np.float32)


class VideoError(OSError):
    """A video file is missing, unreadable, corrupt or cannot be written; names the file."""


@dataclass(frozen=True)
class Frame:
    """One decoded frame.

    Attributes
    ----------
    index : int
        Position in the file (0, 1, 2, ...).
    time : float
        Presentation time [s] on the camera's clock (the frame's pts).
    rgb : numpy.ndarray, shape (height, width, 3), uint8
    """

    index: int
    time: float
    rgb: np.ndarray


@dataclass(frozen=True)
class VideoInfo:
    """What a video file holds: size, rate, frame count (from the container), codec, format."""

    path: Path
    width: int
    height: int
    fps: float
    frame_count: int
    duration: float
    codec: str
    pixel_format: str


def _open(path: str | Path):
    import av

    path = Path(path)
    if not path.is_file():
        raise VideoError(f"{path}: video file not found")
    try:
        container = av.open(str(path))
    except (av.FFmpegError, ValueError, UnicodeDecodeError) as error:
        raise VideoError(f"{path}: not a readable video file ({error})") from None
    if not container.streams.video:
        container.close()
        raise VideoError(f"{path}: holds no video stream")
    return container


def video_info(path: str | Path) -> VideoInfo:
    """Size, frame rate, frame count, codec and pixel format of a video file.

    Raises
    ------
    VideoError
        The file is missing or not a video.
    """
    container = _open(path)
    try:
        stream = container.streams.video[0]
        context = stream.codec_context
        rate = stream.average_rate or stream.guessed_rate or Fraction(0)
        count = int(stream.frames or 0)
        duration = (float(stream.duration * stream.time_base) if stream.duration
                    else float(container.duration or 0) / 1e6)
        if count == 0 and rate:
            count = int(round(duration * float(rate)))
        return VideoInfo(Path(path), int(context.width), int(context.height), float(rate), count,
                         duration, context.name, str(context.pix_fmt))
    finally:
        container.close()


@dataclass(frozen=True)
class Segment:
    """A run of frames that starts at a keyframe and decodes on its own.

    Attributes
    ----------
    start_index : int
        Position of its first frame in the file.
    frame_count : int
    start_pts : int
        Presentation time stamp of its first frame, a keyframe (stream time base).
    stop_pts : int or None
        Time stamp of the next segment's first frame; None: to the end of the file.
    """

    start_index: int
    frame_count: int
    start_pts: int
    stop_pts: int | None


def split_at_keyframes(path: str | Path, parts: int) -> list[Segment]:
    """Cut a video at keyframes into about `parts` segments of similar length.

    Reads the packets' time stamps and keyframe flags (no decoding). Frame ``k`` of the file is
    the packet with the ``k``-th smallest presentation time stamp. A segment begins at a keyframe
    (an IDR frame: x264 closes its groups of pictures, so nothing before it is needed); the cuts
    are the keyframes nearest to ``i n / parts`` (``n`` frames, ``i = 1 .. parts - 1``).

    Returns
    -------
    list of Segment
        In file order, covering every frame; empty when the file has packets without time stamps
        (then it cannot be cut: read it from the start).
    """
    import av

    container = _open(path)
    stamps, keys = [], []
    try:
        stream = container.streams.video[0]
        for packet in container.demux(stream):
            if packet.size == 0:  # the demuxer's final empty packet
                continue
            if packet.pts is None:
                return []
            stamps.append(int(packet.pts))
            if packet.is_keyframe:
                keys.append(int(packet.pts))
    except av.FFmpegError as error:
        raise VideoError(f"{path}: corrupt video data ({error})") from None
    finally:
        container.close()
    order = np.sort(np.array(stamps, dtype=np.int64))
    starts = np.searchsorted(order, np.unique(keys)) if keys else np.zeros(0, int)
    if order.size == 0 or starts.size == 0 or starts[0] != 0:
        return []
    targets = np.arange(1, max(int(parts), 1)) * order.size / max(int(parts), 1)
    cuts = np.unique(starts[np.abs(starts[None, :] - targets[:, None]).argmin(axis=1)]) \
        if targets.size else np.zeros(0, int)
    bounds = [0, *(int(c) for c in cuts if c > 0), int(order.size)]
    return [Segment(a, b - a, int(order[a]), int(order[b]) if b < order.size else None)
            for a, b in zip(bounds[:-1], bounds[1:])]


def _use_threads(stream: Any, threads: bool | str) -> None:
    """FFmpeg's decoder threads: False: one thread; True: "AUTO"; or a thread type."""
    if threads is False or threads is None:
        stream.codec_context.thread_count = 1
    else:
        stream.thread_type = "AUTO" if threads is True else str(threads)
        stream.codec_context.thread_count = 0


def _decoded(path: str | Path, *, threads: bool | str = False,
             segment: Segment | None = None) -> Iterator[Any]:
    """The decoded av.VideoFrame objects of a file (or of a segment), one by one.

    Errors name the file; a segment that does not hold the frames the container lists (a lost
    frame, a seek that missed its keyframe) raises :class:`VideoError`.
    """
    import av

    container = _open(path)
    stream = container.streams.video[0]
    _use_threads(stream, threads)
    index = 0
    try:
        try:
            if segment is not None and segment.start_index > 0:
                container.seek(segment.start_pts, stream=stream, backward=True, any_frame=False)
            for frame in container.decode(stream):
                if segment is not None:
                    if frame.pts < segment.start_pts:
                        continue
                    if segment.stop_pts is not None and frame.pts >= segment.stop_pts:
                        break
                    if index == 0 and frame.pts != segment.start_pts:
                        raise VideoError(f"{path}: seeking to frame {segment.start_index} (pts "
                                         f"{segment.start_pts}) landed at pts {frame.pts}")
                yield frame
                index += 1
        except av.FFmpegError as error:
            raise VideoError(f"{path}: corrupt video data after frame {index} ({error})") from None
    finally:
        container.close()
    if index == 0:
        raise VideoError(f"{path}: no decodable frame (corrupt or empty video)")
    if segment is not None and index != segment.frame_count:
        raise VideoError(f"{path}: frames {segment.start_index} .. "
                         f"{segment.start_index + segment.frame_count - 1}: decoded {index}, the "
                         f"container lists {segment.frame_count}")


def _frame_time(frame: Any, index: int, fallback_rate: float) -> float:
    if frame.pts is not None and frame.time_base is not None:
        return float(frame.pts * frame.time_base)
    return index / fallback_rate


def read_frames(path: str | Path) -> Iterator[Frame]:
    """Stream the frames of a video file as RGB arrays, one at a time.

    Raises
    ------
    VideoError
        Missing, unreadable or corrupt file (also when the corruption shows mid-stream).
    """
    for view in read_frame_views(path):
        yield Frame(view.index, view.time, view.rgb())


class FrameView:
    """A decoded frame whose regions are converted to RGB on demand (no full-frame conversion).

    Parameters
    ----------
    frame : av.VideoFrame
    index : int
    time : float
        Presentation time [s].
    """

    def __init__(self, frame: Any, index: int, time: float) -> None:
        self._frame = frame
        self.index = index
        self.time = time
        self.width = int(frame.width)
        self.height = int(frame.height)
        self.format = frame.format.name
        self._full: np.ndarray | None = None

    def _plane(self, number: int) -> np.ndarray:
        plane = self._frame.planes[number]
        rows = np.frombuffer(plane, dtype=np.uint8).reshape(plane.height, plane.line_size)
        return rows

    def rgb(self) -> np.ndarray:
        """The whole frame as RGB uint8, shape (height, width, 3)."""
        if self._full is None:
            self._full = self._frame.to_ndarray(format="rgb24")
        return self._full

    def crop_channels(self, x0: int, y0: int, x1: int, y1: int
                      ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The R, G, B planes (float32) of a region; from YUV without rounding or clipping.

        Computed element by element (the BT.601 matrix of the module notes, in float32), so a
        pixel gets the same value whatever region it is cut with.
        """
        x0, x1 = max(int(x0), 0), min(int(x1), self.width)
        y0, y1 = max(int(y0), 0), min(int(y1), self.height)
        if self._full is None and self.format in ("yuv444p", "yuvj444p") and x1 > x0 and y1 > y0:
            return self._convert_yuv(x0, y0, x1, y1)
        rgb = self.crop(x0, y0, x1, y1)
        return tuple(rgb[..., k].astype(np.float32) for k in range(3))

    def crop_float(self, x0: int, y0: int, x1: int, y1: int) -> np.ndarray:
        """As :meth:`crop`, in float32; from YUV without rounding or clipping."""
        return np.stack(self.crop_channels(x0, y0, x1, y1), axis=-1)

    def crop(self, x0: int, y0: int, x1: int, y1: int) -> np.ndarray:
        """RGB uint8 of the columns x0..x1-1 and rows y0..y1-1 (clipped to the frame)."""
        x0, x1 = max(int(x0), 0), min(int(x1), self.width)
        y0, y1 = max(int(y0), 0), min(int(y1), self.height)
        if x1 <= x0 or y1 <= y0:
            return np.zeros((max(y1 - y0, 0), max(x1 - x0, 0), 3), dtype=np.uint8)
        if self._full is None:
            if self.format in ("yuv444p", "yuvj444p"):
                rgb = np.stack(self._convert_yuv(x0, y0, x1, y1), axis=-1)
                rgb += 0.5
                return np.clip(rgb, 0, 255, out=rgb).astype(np.uint8)
            if self.format == "gbrp":
                g, b, r = (self._plane(i)[y0:y1, x0:x1] for i in range(3))
                return np.stack([r, g, b], axis=-1)
            if self.format in ("rgb24", "bgr24", "bgr0", "rgb0"):
                step = 3 if self.format.endswith("24") else 4
                packed = self._plane(0)[y0:y1, x0 * step:x1 * step].reshape(y1 - y0, x1 - x0, step)
                order = [0, 1, 2] if self.format.startswith("rgb") else [2, 1, 0]
                return packed[:, :, order].copy()
        return self.rgb()[y0:y1, x0:x1]

    def _convert_yuv(self, x0: int, y0: int, x1: int, y1: int
                     ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        full_range = self.format == "yuvj444p"
        matrix = _YUVJ_TO_RGB if full_range else _YUV_TO_RGB
        offset = _YUVJ_OFFSET if full_range else _YUV_OFFSET
        luma, u, v = (self._plane(k)[y0:y1, x0:x1].astype(np.float32) for k in range(3))
        luma -= offset[0]
        luma *= matrix[0, 0]
        u -= offset[1]
        v -= offset[2]
        red = v * matrix[0, 2]
        red += luma
        green = u * matrix[1, 1]
        green += luma
        green += v * matrix[1, 2]
        blue = u * matrix[2, 1]
        blue += luma
        return red, green, blue


def read_frame_views(path: str | Path, *, threads: bool | str = False,
                     segment: Segment | None = None) -> Iterator[FrameView]:
    """Stream :class:`FrameView` objects (regions converted to RGB on demand).

    Parameters
    ----------
    path : str or pathlib.Path
    threads : bool or str
        FFmpeg's decoder threads: False (default) one thread, True ``"AUTO"``, or a thread type
        (``"SLICE"``, ``"FRAME"``). Measured on 1080p x264 clips (``benchmarks/
        video_tracking_speed.md``): frame threads cost about 10 % more CPU per frame and help
        the wall clock only on an idle machine; several processes on segments scale better.
    segment : Segment, optional
        Read only this part (see :func:`split_at_keyframes`); indices stay those of the file.
    """
    rate = 0.0
    first = 0 if segment is None else segment.start_index
    for index, frame in enumerate(_decoded(path, threads=threads, segment=segment), start=first):
        if frame.pts is None and not rate:
            rate = video_info(path).fps or 50.0
        yield FrameView(frame, index, _frame_time(frame, index, rate))


class VideoWriter:
    """Encode RGB frames into a video file, one at a time (a context manager).

    Parameters
    ----------
    path : str or pathlib.Path
        Output file; the container follows the suffix (``.mp4``, ``.mkv``, ``.avi`` ...).
    width, height : int
        Frame size [px] (even numbers for ``"h264-420"``).
    fps : float
        Frame rate; frame ``k`` gets the presentation time ``k / fps``.
    codec : {"h264", "h264-420", "lossless"}
    crf : float
        Constant rate factor of libx264 (lower is better; 0 is not lossless in YUV).
    preset : str, optional
        libx264 speed preset; default ``"superfast"`` for H.264 and ``"ultrafast"`` for lossless
        (without CABAC: a noisy lossless frame decodes several times faster).
    keyframe_interval : float
        Largest time between two keyframes (IDR frames) [s]; default 1 s (50 frames at 50
        frames/s, libx264's own default is 250). Every keyframe starts a group of pictures that
        decodes on its own, so a reader can split the file there and decode the parts in parallel
        (:func:`panto.video_sync.tracking.track_video`); the cost is a slightly larger file.

    Examples
    --------
    >>> with VideoWriter("out.mp4", 640, 360, 50.0) as writer:   # doctest: +SKIP
    ...     writer.write(rgb)
    """

    def __init__(self, path: str | Path, width: int, height: int, fps: float = 50.0, *,
                 codec: str = "h264", crf: float = 18.0, preset: str | None = None,
                 keyframe_interval: float = 1.0) -> None:
        import av

        if codec not in CODECS:
            raise ValueError(f"codec {codec!r}: use one of {CODECS}")
        self.path = Path(path)
        self.width, self.height, self.fps, self.codec = int(width), int(height), float(fps), codec
        self.frame_count = 0
        encoder, pixel_format = _ENCODERS[codec]
        options = {"preset": preset or ("ultrafast" if codec == "lossless" else "superfast")}
        options.update({"qp": "0"} if codec == "lossless" else {"crf": f"{crf:g}"})
        try:
            self._container = av.open(str(self.path), "w")
            rate = Fraction(self.fps).limit_denominator(1001)
            self._stream = self._container.add_stream(encoder, rate=rate)
            self._stream.width, self._stream.height = self.width, self.height
            self._stream.pix_fmt = pixel_format
            self._stream.codec_context.gop_size = max(1, int(round(keyframe_interval * self.fps)))
            self._stream.codec_context.time_base = 1 / rate
            self._stream.options = options
        except (av.FFmpegError, ValueError) as error:
            raise VideoError(f"{self.path}: cannot create a {codec} video ({error})") from None
        self._time_base = 1 / rate

    def write(self, rgb: np.ndarray) -> None:
        """Encode one RGB uint8 frame of shape (height, width, 3)."""
        import av

        rgb = np.asarray(rgb)
        if rgb.shape != (self.height, self.width, 3) or rgb.dtype != np.uint8:
            raise ValueError(f"{self.path}: frame {self.frame_count} must be uint8 of shape "
                             f"{(self.height, self.width, 3)}, got {rgb.dtype} {rgb.shape}")
        frame = av.VideoFrame.from_ndarray(np.ascontiguousarray(rgb), format="rgb24")
        frame.pts = self.frame_count
        frame.time_base = self._time_base
        self._mux(self._stream.encode(frame))
        self.frame_count += 1

    def _mux(self, packets: Any) -> None:
        import av

        try:
            self._container.mux(packets)
        except av.FFmpegError as error:
            raise VideoError(f"{self.path}: writing failed ({error})") from None

    def close(self) -> None:
        """Flush the encoder and close the file."""
        if self._container is None:
            return
        try:
            self._mux(self._stream.encode())
        finally:
            self._container.close()
            self._container = None

    def __enter__(self) -> "VideoWriter":
        return self

    def __exit__(self, *exc_info: Any) -> None:
        self.close()
