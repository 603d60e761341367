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


def _decoded(path: str | Path, *, threads: bool = True) -> Iterator[Any]:
    """The decoded av.VideoFrame objects of a file, one by one; errors name the file."""
    import av

    container = _open(path)
    stream = container.streams.video[0]
    if threads:
        stream.thread_type = "AUTO"
    index = 0
    try:
        try:
            for frame in container.decode(stream):
                yield frame
                index += 1
        except av.FFmpegError as error:
            raise VideoError(f"{path}: corrupt video data after frame {index} ({error})") from None
    finally:
        container.close()
    if index == 0:
        raise VideoError(f"{path}: no decodable frame (corrupt or empty video)")


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

    def crop_float(self, x0: int, y0: int, x1: int, y1: int) -> np.ndarray:
        """As :meth:`crop`, in float32; from YUV without rounding or clipping (faster)."""
        x0, x1 = max(int(x0), 0), min(int(x1), self.width)
        y0, y1 = max(int(y0), 0), min(int(y1), self.height)
        if self._full is None and self.format in ("yuv444p", "yuvj444p") and x1 > x0 and y1 > y0:
            return self._crop_yuv(x0, y0, x1, y1, rounded=False)
        return self.crop(x0, y0, x1, y1).astype(np.float32)

    def crop(self, x0: int, y0: int, x1: int, y1: int) -> np.ndarray:
        """RGB uint8 of the columns x0..x1-1 and rows y0..y1-1 (clipped to the frame)."""
        x0, x1 = max(int(x0), 0), min(int(x1), self.width)
        y0, y1 = max(int(y0), 0), min(int(y1), self.height)
        if x1 <= x0 or y1 <= y0:
            return np.zeros((max(y1 - y0, 0), max(x1 - x0, 0), 3), dtype=np.uint8)
        if self._full is None:
            if self.format in ("yuv444p", "yuvj444p"):
                return self._crop_yuv(x0, y0, x1, y1)
            if self.format == "gbrp":
                g, b, r = (self._plane(i)[y0:y1, x0:x1] for i in range(3))
                return np.stack([r, g, b], axis=-1)
            if self.format in ("rgb24", "bgr24", "bgr0", "rgb0"):
                step = 3 if self.format.endswith("24") else 4
                packed = self._plane(0)[y0:y1, x0 * step:x1 * step].reshape(y1 - y0, x1 - x0, step)
                order = [0, 1, 2] if self.format.startswith("rgb") else [2, 1, 0]
                return packed[:, :, order].copy()
        return self.rgb()[y0:y1, x0:x1]

    def _crop_yuv(self, x0: int, y0: int, x1: int, y1: int, *, rounded: bool = True
                  ) -> np.ndarray:
        yuv = np.empty((y1 - y0, x1 - x0, 3), dtype=np.float32)
        for number in range(3):
            yuv[..., number] = self._plane(number)[y0:y1, x0:x1]
        full_range = self.format == "yuvj444p"
        yuv -= _YUVJ_OFFSET if full_range else _YUV_OFFSET
        rgb = yuv @ (_YUVJ_TO_RGB if full_range else _YUV_TO_RGB).T
        if not rounded:
            return rgb
        rgb += 0.5
        return np.clip(rgb, 0, 255, out=rgb).astype(np.uint8)


def read_frame_views(path: str | Path, *, threads: bool = True) -> Iterator[FrameView]:
    """Stream :class:`FrameView` objects (regions converted to RGB on demand)."""
    rate = 0.0
    for index, frame in enumerate(_decoded(path, threads=threads)):
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

    Examples
    --------
    >>> with VideoWriter("out.mp4", 640, 360, 50.0) as writer:   # doctest: +SKIP
    ...     writer.write(rgb)
    """

    def __init__(self, path: str | Path, width: int, height: int, fps: float = 50.0, *,
                 codec: str = "h264", crf: float = 18.0, preset: str | None = None) -> None:
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
