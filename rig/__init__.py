"""The rig sidecar and its virtual test bed (thesis chapter 3).

- Excitation: :mod:`~panto.rig.signals` (APRBS, ramps, sines), :mod:`~panto.rig.profiles` (rig profiles
  as files), :mod:`~panto.rig.conditioning` (limiter and filter of the motor command),
  :mod:`~panto.rig.profile_preview` (a profile rendered before it is run).
- The linear motor over CAN: :mod:`~panto.rig.can_protocol` (frames from ``linear_motor.dbc``),
  :mod:`~panto.rig.drive` (the driver), :mod:`~panto.rig.drive_emulator` (the drive, emulated).
- Pressure and synchronisation: :mod:`~panto.rig.pressure`, :mod:`~panto.rig.pneumatics`,
  :mod:`~panto.rig.sync_led`.
- A run: :mod:`~panto.rig.session` (one run on a real or virtual rig), :mod:`~panto.rig.recorder`,
  :mod:`~panto.rig.dataset` (the run's files: CSV, Parquet, MAT and a metadata side file),
  :mod:`~panto.rig.clock`, :mod:`~panto.rig.realtime` (against the wall clock).
- The virtual test bed: :mod:`~panto.rig.testbed` (the pantograph FMU on the emulated rig),
  :mod:`~panto.rig.imperfections` (what a real rig adds), :mod:`~panto.rig.virtual` (a profile played
  on it and recorded).
"""

from panto import lazy_exports

# public names, imported on first use (importing the package stays cheap)
__all__, __getattr__, __dir__ = lazy_exports(__name__, {
    "read_dataset": "dataset",
    "Dataset": "dataset",
    "RunMetadata": "dataset",
    "DatasetError": "dataset",
    "load_profile": "profiles",
    "run_profile": "session",
    "RunOptions": "session",
    "RigIO": "session",
    "run_virtual_profile": "virtual",
    "RigImperfections": "imperfections",
    "LinearMotorDriver": "drive",
})
