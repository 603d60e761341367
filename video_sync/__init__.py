"""The video sidecar: marker tracking, LED read-out and synchronisation with the rig's run.

- :mod:`~panto.video_sync.camera`: the synthetic camera of the virtual test bed (renders a run).
- :mod:`~panto.video_sync.video_io`: reading and writing real encoded video (PyAV).
- :mod:`~panto.video_sync.setup`, :mod:`~panto.video_sync.tracking`: the tracker's set-up and the marker
  and LED read-out per frame; :mod:`~panto.video_sync.track_file` the track as a file.
- :mod:`~panto.video_sync.synchronisation`, :mod:`~panto.video_sync.merge`: the LED's PRBS aligned with
  the run's, and the track merged into the run's dataset.
"""

from panto import lazy_exports

# public names, imported on first use (importing the package stays cheap)
__all__, __getattr__, __dir__ = lazy_exports(__name__, {
    "render_run": "camera",
    "VideoWriter": "video_io",
    "read_frames": "video_io",
    "video_info": "video_io",
    "make_setup": "setup",
    "MarkerTracker": "tracking",
    "synchronise": "synchronisation",
    "sync_and_merge": "merge",
    "MergeOptions": "merge",
})
