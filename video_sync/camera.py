"""The synthetic camera: the virtual test bed's markers and LED, filmed and encoded to a real video.

What is rendered (thesis section 3.2, Fig. 3.9): a grey, slightly textured screen behind the
pantograph; coloured disc markers on the pan-head ``(x_cb, xi)``, the cross bar ``(x_cb, y_cb)`` and
the slider/bar ``(x_cb, eta)``, each at its own horizontal offset so they do not overlap, plus a
fixed ``reference`` marker on the screen; the synchronisation LED (a small red disc) on the screen;
a few small specks of marker colour on the screen (what the morphological opening must remove);
a slow global drift of the lighting and a frame-to-frame flicker; sensor noise; and a shadow that
hides one marker for a known set of frames.

Geometry: a marker with anchor pixel ``(c_a, r_a)``, anchor position ``(x_a, y_a)`` [m] and scale
``(s_x, s_y)`` [mm/px] is drawn at

.. math::

    c = c_a + \\frac{x - x_a}{10^{-3} s_x}, \\qquad r = r_a - \\frac{y - y_a}{10^{-3} s_y}

(image rows grow downwards, heights upwards). Pixel ``(r, c)`` covers ``[c - 1/2, c + 1/2] x
[r - 1/2, r + 1/2]``; a disc's pixel value is the area-weighted mix of marker and background, the
covered area found by 8 x 8 supersampling, so sub-pixel positions are true in the image.

Timing: the camera runs at 50 frames/s with a 2 ms shutter, which is exactly one sample of the
500 Hz truth. Frame ``k`` therefore shows sample ``start_sample + 10 k`` (its marker positions and
its LED bit); ``start_sample`` is the unknown instant the camera was started, drawn at random.
"""
from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any, Callable, Mapping

import numpy as np

from panto.video_sync.video_io import VideoWriter

CAMERA_FORMAT = "panto-camera-video"
_SUPERSAMPLING = 8


@dataclass(frozen=True)
class MarkerDrawing:
    """One disc marker as the camera sees it.

    Attributes
    ----------
    name : str
    x_channel, y_channel : str or None
        Truth channels of its horizontal and vertical position [m]; None: fixed at the anchor.
    colour : tuple of int
        RGB 0..255 under nominal lighting.
    radius_px : float
    mm_per_px : tuple of float
        Scale (horizontal, vertical) in the marker's plane [mm/px].
    anchor_px : tuple of float
        Pixel (column, row) where the marker is when at `anchor_m`.
    anchor_m : tuple of float
        Position (x, y) [m] that maps to `anchor_px`.
    """

    name: str
    x_channel: str | None
    y_channel: str | None
    colour: tuple[int, int, int]
    radius_px: float
    mm_per_px: tuple[float, float]
    anchor_px: tuple[float, float]
    anchor_m: tuple[float, float]

    def to_pixels(self, x: float, y: float) -> tuple[float, float]:
        """Pixel (column, row) of position (x, y) [m]."""
        return (self.anchor_px[0] + (x - self.anchor_m[0]) / (1e-3 * self.mm_per_px[0]),
                self.anchor_px[1] - (y - self.anchor_m[1]) / (1e-3 * self.mm_per_px[1]))


@dataclass(frozen=True)
class LedDrawing:
    """The synchronisation LED: a small disc, bright red when on, dark when off."""

    centre_px: tuple[float, float] = (1760.0, 160.0)
    radius_px: float = 5.0
    on_colour: tuple[int, int, int] = (255, 70, 50)
    off_colour: tuple[int, int, int] = (75, 50, 50)


@dataclass(frozen=True)
class ShadowEvent:
    """A shadow that hides `marker` on frames first_frame .. first_frame + frame_count - 1."""

    marker: str = "cross_bar"
    first_frame: int = 75
    frame_count: int = 20
    darkening: float = 0.2
    """Light left in the shadow (fraction)."""

    def covers(self, frame: int) -> bool:
        return self.first_frame <= frame < self.first_frame + self.frame_count


def _default_markers() -> tuple[MarkerDrawing, ...]:
    return (
        MarkerDrawing("pan_head", "x_cb", "xi", (40, 200, 60), 12.0, (0.50, 0.50), (640.0, 540.0),
                      (0.105, 2.0)),
        MarkerDrawing("cross_bar", "x_cb", "y_cb", (40, 90, 225), 12.0, (0.48, 0.48),
                      (960.0, 540.0), (0.105, 2.0)),
        MarkerDrawing("slider", "x_cb", "eta", (215, 40, 200), 12.0, (0.52, 0.52),
                      (1280.0, 540.0), (0.105, 2.0)),
        MarkerDrawing("reference", None, None, (235, 200, 30), 12.0, (0.50, 0.50),
                      (1600.0, 300.0), (0.0, 0.0)),
    )


@dataclass(frozen=True)
class CameraSetup:
    """The synthetic camera: frame, timing, markers, screen, LED, lighting, noise, shadow.

    The default maps about 0.5 mm to a pixel, so the +-0.13 m motion range around the operating
    height of 2.0 m spans rows 280 .. 800 of the 1080.
    """

    width: int = 1920
    height: int = 1080
    fps: float = 50.0
    shutter: float = 0.002
    truth_rate: float = 500.0
    markers: tuple[MarkerDrawing, ...] = field(default_factory=_default_markers)
    background: tuple[int, int, int] = (150, 150, 150)
    texture_amplitude: float = 10.0
    texture_scale_px: float = 30.0
    specks: int = 40
    led: LedDrawing = LedDrawing()
    gain_drift: float = 0.08
    gain_drift_period: float = 37.0
    flicker: float = 0.015
    noise_std: float = 2.0
    shadow: ShadowEvent | None = ShadowEvent()

    def __post_init__(self) -> None:
        step = self.truth_rate / self.fps
        if abs(step - round(step)) > 1e-9 or step < 1:
            raise ValueError(f"camera: truth_rate/fps = {step} must be a whole number")
        if abs(self.shutter - 1.0 / self.truth_rate) > 1e-12:
            raise ValueError(f"camera: shutter {self.shutter} s must equal one truth sample "
                             f"({1.0 / self.truth_rate} s)")
        names = [m.name for m in self.markers]
        if len(set(names)) != len(names):
            raise ValueError(f"camera: duplicated marker names {names}")
        if self.shadow is not None and self.shadow.marker not in names:
            raise ValueError(f"camera: shadow marker {self.shadow.marker!r} not in {names}")

    @property
    def sample_step(self) -> int:
        """Truth samples per frame (10 for 500 Hz and 50 frames/s)."""
        return int(round(self.truth_rate / self.fps))

    def marker(self, name: str) -> MarkerDrawing:
        for marker in self.markers:
            if marker.name == name:
                return marker
        raise KeyError(f"camera: no marker {name!r}")

    def reduced(self, factor: float) -> "CameraSetup":
        """The same scene at a `factor` of the resolution (for fast tests); radii stay >= 6 px."""
        markers = tuple(replace(m, radius_px=max(m.radius_px * factor, 6.0),
                                mm_per_px=(m.mm_per_px[0] / factor, m.mm_per_px[1] / factor),
                                anchor_px=(m.anchor_px[0] * factor, m.anchor_px[1] * factor))
                        for m in self.markers)
        led = replace(self.led, centre_px=(self.led.centre_px[0] * factor,
                                           self.led.centre_px[1] * factor),
                      radius_px=max(self.led.radius_px * factor, 3.0))
        return replace(self, width=2 * int(round(self.width * factor / 2)),
                       height=2 * int(round(self.height * factor / 2)), markers=markers, led=led,
                       texture_scale_px=self.texture_scale_px * factor)

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)

    @classmethod
    def from_dict(cls, data: Mapping[str, Any], *, where: str = "camera") -> "CameraSetup":
        """Rebuild from :meth:`to_dict`; a missing or wrong field raises naming it."""
        try:
            values = dict(data)
            values["markers"] = tuple(MarkerDrawing(**{k: (tuple(v) if isinstance(v, list) else v)
                                                       for k, v in m.items()})
                                      for m in values["markers"])
            values["led"] = LedDrawing(**{k: (tuple(v) if isinstance(v, list) else v)
                                          for k, v in values["led"].items()})
            if values.get("shadow") is not None:
                values["shadow"] = ShadowEvent(**values["shadow"])
            values["background"] = tuple(values["background"])
            return cls(**values)
        except (KeyError, TypeError, AttributeError) as error:
            raise ValueError(f"{where}: not a camera set-up ({error})") from None


@dataclass(frozen=True)
class RenderResult:
    """What :func:`render_run` wrote, with the truth of every frame (for tests).

    Attributes
    ----------
    path, camera_json : pathlib.Path
        The video and its JSON side file.
    start_sample : int
        Truth sample shown by frame 0 (the unknown start instant, truth for tests).
    start_time : float
        Its time [s] on the run's time base.
    fps : float
    frame_count : int
    pixels : dict of str to numpy.ndarray, shape (frame_count, 2)
        True (column, row) of each marker's centre.
    visible : dict of str to numpy.ndarray of bool
        False where the shadow hides the marker.
    led : numpy.ndarray of int
        The LED bit each frame shows.
    """

    path: Path
    camera_json: Path
    start_sample: int
    start_time: float
    fps: float
    frame_count: int
    pixels: dict[str, np.ndarray]
    visible: dict[str, np.ndarray]
    led: np.ndarray


def _smooth_texture(shape: tuple[int, int], scale: float, rng: np.random.Generator) -> np.ndarray:
    """A zero-mean, unit-spread random field smoothed over `scale` pixels."""
    from scipy.ndimage import gaussian_filter

    coarse = max(int(scale / 4), 1)
    small = rng.standard_normal((shape[0] // coarse + 2, shape[1] // coarse + 2))
    small = gaussian_filter(small, scale / coarse / 2)
    field_ = np.repeat(np.repeat(small, coarse, axis=0), coarse, axis=1)[:shape[0], :shape[1]]
    return (field_ - field_.mean()) / (field_.std() + 1e-12)


def disc_coverage(centre: tuple[float, float], radius: float, box: tuple[int, int, int, int]
                  ) -> np.ndarray:
    """Fraction of each pixel of `box` = (x0, y0, x1, y1) covered by a disc (8 x 8 supersampling).

    Pixel (r, c) is the square [c - 1/2, c + 1/2] x [r - 1/2, r + 1/2]; `centre` is (column, row).
    """
    x0, y0, x1, y1 = box
    offsets = (np.arange(_SUPERSAMPLING) + 0.5) / _SUPERSAMPLING - 0.5
    columns = (np.arange(x0, x1)[:, None] + offsets[None, :]).ravel() - centre[0]
    rows = (np.arange(y0, y1)[:, None] + offsets[None, :]).ravel() - centre[1]
    inside = rows[:, None] ** 2 + columns[None, :] ** 2 <= radius * radius
    return inside.reshape(y1 - y0, _SUPERSAMPLING, x1 - x0, _SUPERSAMPLING).mean(axis=(1, 3))


class CameraRenderer:
    """Renders frames of a :class:`CameraSetup`; the static screen is made once.

    Parameters
    ----------
    setup : CameraSetup
    rng : numpy.random.Generator
    """

    _BANK = 4  # noisy copies of the screen, cycled (the noise that matters is redrawn)

    def __init__(self, setup: CameraSetup, rng: np.random.Generator) -> None:
        self.setup = setup
        self.rng = rng
        shape = (setup.height, setup.width)
        texture = _smooth_texture(shape, setup.texture_scale_px, rng) * setup.texture_amplitude
        rows, columns = np.mgrid[0:shape[0], 0:shape[1]]
        vignette = 1.0 - 0.15 * (((columns - shape[1] / 2) / shape[1]) ** 2
                                 + ((rows - shape[0] / 2) / shape[0]) ** 2)
        screen = (np.asarray(setup.background, float)[None, None, :] * vignette[..., None]
                  + texture[..., None])
        self._draw_specks(screen)
        self.screen = screen.astype(np.float32)
        self._bank = [np.clip(screen + rng.normal(0, setup.noise_std, screen.shape) + 0.5, 0, 255
                              ).astype(np.uint8) for _ in range(self._BANK)]
        self._phase = rng.uniform(0, 2 * math.pi)

    def _draw_specks(self, screen: np.ndarray) -> None:
        """Small specks (1-2 px) of marker colours, kept clear of the markers' paths."""
        setup = self.setup
        moving = [m for m in setup.markers if m.x_channel is not None]
        for _ in range(setup.specks):
            marker = setup.markers[self.rng.integers(len(setup.markers))]
            column = int(self.rng.integers(2, setup.width - 4))
            row = int(self.rng.integers(2, setup.height - 4))
            clear = all(abs(column - m.anchor_px[0]) > 3 * m.radius_px + 40 for m in moving)
            fixed_clear = all(math.hypot(column - m.anchor_px[0], row - m.anchor_px[1])
                              > 3 * m.radius_px for m in setup.markers if m.x_channel is None)
            if clear and fixed_clear:
                size = int(self.rng.integers(1, 3))
                screen[row:row + size, column:column + size] = marker.colour

    def gain(self, frame: int) -> float:
        """Lighting gain of a frame: slow drift plus flicker."""
        setup = self.setup
        drift = setup.gain_drift * math.sin(2 * math.pi * frame / setup.fps
                                            / setup.gain_drift_period + self._phase)
        return float(1.0 + drift + setup.flicker * self.rng.standard_normal())

    def render(self, frame: int, positions: Mapping[str, tuple[float, float]], led: int
               ) -> tuple[np.ndarray, dict[str, tuple[float, float]], dict[str, bool]]:
        """One frame: RGB uint8, marker centres (column, row) and visibility."""
        setup = self.setup
        gain = self.gain(frame)
        image = self.lit_screen(frame, gain)
        pixels, visible = {}, {}
        for marker in setup.markers:
            x, y = positions.get(marker.name, marker.anchor_m)
            centre = marker.to_pixels(x, y)
            shadowed = setup.shadow is not None and setup.shadow.marker == marker.name \
                and setup.shadow.covers(frame)
            self._paint_disc(image, centre, marker.radius_px, marker.colour, gain,
                             shadow=setup.shadow.darkening if shadowed else None)
            pixels[marker.name] = centre
            visible[marker.name] = not shadowed and self._inside(centre, marker.radius_px)
        colour = setup.led.on_colour if led else setup.led.off_colour
        self._paint_disc(image, setup.led.centre_px, setup.led.radius_px, colour, gain)
        return image, pixels, visible

    def lit_screen(self, frame: int, gain: float) -> np.ndarray:
        """The frame's noisy screen under the lighting `gain`, RGB uint8 (a new array).

        Each pixel is ``uint8(clip(v gain + 1/2, 0, 255))`` of its value ``v`` in one of the
        noisy copies of the screen, looked up in a 256-entry table (``take``: about half the
        time of fancy indexing on a 960 x 540 frame, the same values).
        """
        lut = np.clip(np.arange(256) * gain + 0.5, 0, 255).astype(np.uint8)
        return lut.take(self._bank[frame % self._BANK])

    def _inside(self, centre: tuple[float, float], radius: float) -> bool:
        return (radius <= centre[0] <= self.setup.width - 1 - radius
                and radius <= centre[1] <= self.setup.height - 1 - radius)

    def _paint_disc(self, image: np.ndarray, centre: tuple[float, float], radius: float,
                    colour: tuple[int, int, int], gain: float, *, shadow: float | None = None
                    ) -> None:
        reach = radius * (2.5 if shadow is not None else 1.0) + 2
        x0 = max(int(math.floor(centre[0] - reach)), 0)
        y0 = max(int(math.floor(centre[1] - reach)), 0)
        x1 = min(int(math.ceil(centre[0] + reach)) + 1, self.setup.width)
        y1 = min(int(math.ceil(centre[1] + reach)) + 1, self.setup.height)
        if x1 <= x0 or y1 <= y0:
            return
        alpha = disc_coverage(centre, radius, (x0, y0, x1, y1))[..., None]
        patch = self.screen[y0:y1, x0:x1] * (1 - alpha) + np.asarray(colour, np.float32) * alpha
        light = gain
        if shadow is not None:  # soft-edged shadow of 2.5 radii
            rows, columns = np.mgrid[y0:y1, x0:x1]
            distance = np.hypot(columns - centre[0], rows - centre[1]) / (2.5 * radius)
            edge = np.clip((distance - 0.8) / 0.2, 0, 1)
            light = gain * (shadow + (1 - shadow) * edge)[..., None]
        patch = patch * light + self.rng.normal(0, self.setup.noise_std, patch.shape)
        image[y0:y1, x0:x1] = np.clip(patch + 0.5, 0, 255).astype(np.uint8)


def _load_truth(source: Any):
    from panto.rig.dataset import Dataset, read_csv
    from panto.rig.virtual import TRUTH_FILE

    if isinstance(source, Dataset):
        return source, None
    path = Path(source)
    path = path / TRUTH_FILE if path.is_dir() else path
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no truth file (a virtual run folder holds {TRUTH_FILE})")
    return read_csv(path, required=()), path


def _check_truth(truth: Any, setup: CameraSetup, where: str) -> None:
    needed = {c for m in setup.markers for c in (m.x_channel, m.y_channel) if c} | {"led"}
    missing = sorted(needed - set(truth.names))
    if missing:
        raise ValueError(f"{where}: truth channel(s) {missing} missing")
    if len(truth) < 2:
        raise ValueError(f"{where}: truth has fewer than two samples")
    period = float(np.median(np.diff(truth.time)))
    if abs(period * setup.truth_rate - 1) > 1e-6:
        raise ValueError(f"{where}: truth sampled every {period} s, the camera expects "
                         f"{1 / setup.truth_rate} s")


def render_run(source: Any, out_path: str | Path, *, setup: CameraSetup | None = None,
               codec: str = "h264", start_sample: int | None = None,
               rng: np.random.Generator | int | None = None, duration: float | None = None,
               crf: float = 18.0, preset: str | None = None,
               progress: Callable[[str], None] | None = None) -> RenderResult:
    """Film a virtual run: render its markers and LED frame by frame and encode them.

    Parameters
    ----------
    source : str, pathlib.Path or panto.rig.dataset.Dataset
        A virtual run folder (its ``truth.csv``), a truth CSV file, or a truth dataset at 500 Hz
        with the channels the markers use (``x_cb``, ``y_cb``, ``xi``, ``eta``) and ``led``.
    out_path : str or pathlib.Path
        Video file (``.mp4`` or ``.mkv``); ``<out_path>.json`` receives the camera set-up.
    setup : CameraSetup, optional
    codec : {"h264", "h264-420", "lossless"}
    start_sample : int, optional
        Truth sample shown by frame 0; default: drawn from `rng` in 0 .. 1000 (0 .. 2 s).
    rng : numpy.random.Generator or int, optional
    duration : float, optional
        Film at most this long [s].
    crf : float
        libx264 quality for the H.264 codecs.
    preset : str, optional
        libx264 speed preset (default: :class:`panto.video_sync.video_io.VideoWriter`'s).
    progress : callable, optional

    Returns
    -------
    RenderResult
    """
    setup = setup or CameraSetup()
    rng = rng if isinstance(rng, np.random.Generator) else np.random.default_rng(rng)
    truth, truth_path = _load_truth(source)
    where = str(truth_path or "truth dataset")
    _check_truth(truth, setup, where)
    start_sample, frame_count = _frames_to_film(len(truth), setup, start_sample, duration, rng,
                                                where)
    renderer = CameraRenderer(setup, rng)
    out_path = Path(out_path)
    with VideoWriter(out_path, setup.width, setup.height, setup.fps, codec=codec, crf=crf,
                     preset=preset) as writer:
        pixels, visible, led = _film(truth, setup, renderer, writer, start_sample, frame_count,
                                     progress)
    start_time = float(truth.time[start_sample])
    side = _write_camera_json(out_path, setup, codec, frame_count, start_sample, start_time,
                              truth_path)
    return RenderResult(out_path, side, start_sample, start_time, setup.fps, frame_count, pixels,
                        visible, led.astype(int))


def _frames_to_film(samples: int, setup: CameraSetup, start_sample: int | None,
                    duration: float | None, rng: np.random.Generator,
                    where: str) -> tuple[int, int]:
    """The truth sample shown by frame 0 (drawn from `rng` if not given) and the frame count."""
    if start_sample is None:
        start_sample = int(rng.integers(0, min(1000, samples // 4) + 1))
    if not 0 <= start_sample < samples:
        raise ValueError(f"{where}: start_sample {start_sample} outside 0 .. {samples - 1}")
    frame_count = (samples - 1 - start_sample) // setup.sample_step + 1
    if duration is not None:
        frame_count = min(frame_count, int(math.floor(duration * setup.fps)) + 1)
    return start_sample, frame_count


def _film(truth: Any, setup: CameraSetup, renderer: CameraRenderer, writer: VideoWriter,
          start_sample: int, frame_count: int, progress: Callable[[str], None] | None,
          ) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray], np.ndarray]:
    """Render and encode the frames; the marker centres [px], their visibility, the LED bits."""
    pixels = {m.name: np.empty((frame_count, 2)) for m in setup.markers}
    visible = {m.name: np.empty(frame_count, dtype=bool) for m in setup.markers}
    led = np.empty(frame_count, dtype=np.int8)
    columns = {c: np.asarray(truth[c]) for m in setup.markers
               for c in (m.x_channel, m.y_channel) if c}
    step = setup.sample_step
    for k in range(frame_count):
        sample = start_sample + step * k
        positions = {m.name: (columns[m.x_channel][sample], columns[m.y_channel][sample])
                     for m in setup.markers if m.x_channel}
        led[k] = int(round(float(truth["led"][sample])))
        image, centres, shown = renderer.render(k, positions, led[k])
        writer.write(image)
        for name in centres:
            pixels[name][k], visible[name][k] = centres[name], shown[name]
        if progress and (k + 1) % 500 == 0:
            progress(f"rendered {k + 1}/{frame_count} frames")
    return pixels, visible, led


def camera_json_path(video: str | Path) -> Path:
    """The camera side file of a rendered video: ``<video>.json``."""
    video = Path(video)
    return video.with_name(video.name + ".json")


def _write_camera_json(video: Path, setup: CameraSetup, codec: str, frame_count: int,
                       start_sample: int, start_time: float, truth_path: Path | None) -> Path:
    shadow = setup.shadow
    document = {
        "format": CAMERA_FORMAT, "version": 1, "video": video.name, "codec": codec,
        "fps": setup.fps, "frame_count": frame_count, "camera": setup.to_dict(),
        "truth_for_tests_only": {
            "note": "what generated the video; a tracker or synchroniser must not read this",
            "start_sample": start_sample, "start_time": start_time,
            "sample_step": setup.sample_step,
            "truth_file": str(truth_path) if truth_path else None,
            "shadow_frames": ({shadow.marker: [shadow.first_frame,
                                               shadow.first_frame + shadow.frame_count - 1]}
                              if shadow else {}),
        },
    }
    path = camera_json_path(video)
    path.write_text(json.dumps(document, indent=2))
    return path


def load_camera_json(path: str | Path) -> CameraSetup:
    """The :class:`CameraSetup` of a camera side file (``<video>.json``)."""
    path = Path(path)
    try:
        document = json.loads(path.read_text())
    except (OSError, json.JSONDecodeError) as error:
        raise ValueError(f"{path}: not a readable camera side file ({error})") from None
    if not isinstance(document, dict) or document.get("format") != CAMERA_FORMAT:
        raise ValueError(f"{path}: not a {CAMERA_FORMAT!r} file")
    if "camera" not in document:
        raise ValueError(f"{path}: field 'camera' missing")
    return CameraSetup.from_dict(document["camera"], where=str(path))
