"""Datasets and the recorder: bit-exact round trips, the schema check's refusals, incremental
writing that survives exceptions and crashes, never overwriting."""
import json
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest
from scipy.io import loadmat, savemat

from panto.rig.dataset import (REQUIRED_CHANNELS, STANDARD_CHANNELS, Dataset, DatasetError,
                         RunMetadata, read_dataset)
from panto.rig.recorder import Recorder, new_run_folder

N = 1500


def awkward_floats(rng, n):
    """Values whose decimal text is long or special: every magnitude, signs, subnormals."""
    values = rng.normal(size=n) * 10.0 ** rng.uniform(-300, 300, n)
    values[:6] = [5e-324, -0.0, 1 / 3, 2 ** -1074 * 3, 1.7976931348623157e308, 0.1 + 0.2]
    return values


def make_dataset(seed=0):
    rng = np.random.default_rng(seed)
    time = np.cumsum(rng.uniform(0.001, 0.003, N))
    channels = {name: awkward_floats(rng, N) for name in STANDARD_CHANNELS}
    channels["led"] = rng.integers(0, 2, N).astype(float)
    for name, spec in STANDARD_CHANNELS.items():
        if spec.allow_nan:
            channels[name][rng.integers(0, N, 20)] = np.nan
    channels["bar_acceleration"] = awkward_floats(rng, N)
    metadata = RunMetadata(sample_rate=500.0, source="emulator", seed=12,
                           profile={"name": "p", "motor": {"offset": 0.15}}, notes="ünïcode",
                           truth={"bar_mass": 1.5, "friction": [0.1, 2]},
                           extra={"operator": "test"})
    return Dataset(time, channels, {"bar_acceleration": "m/s^2"}, metadata)


def same_bits(a, b):
    return np.array_equal(np.asarray(a).view(np.int64), np.asarray(b).view(np.int64))


@pytest.mark.parametrize("suffix", [".csv", ".parquet", ".mat"])
def test_round_trip_is_bit_exact(tmp_path, suffix):
    dataset = make_dataset()
    back = read_dataset(dataset.write(tmp_path / f"run{suffix}"))
    assert back.names == dataset.names and dict(back.units) == dict(dataset.units)
    assert same_bits(back.time, dataset.time)
    for name in dataset.names:
        assert same_bits(back[name], dataset[name]), name
    assert back.metadata == dataset.metadata and back.warnings == ()


# --- refusals -----------------------------------------------------------------------------------

def minimal_csv(tmp_path, header=None, rows=None, units=None, name="bad.csv"):
    """A CSV + side file with the required channels, to be spoiled by the caller."""
    header = header or ["time [s]"] + [f"{n} [{STANDARD_CHANNELS[n].unit}]"
                                       for n in REQUIRED_CHANNELS]
    rows = rows or [[f"{k * 0.002!r}"] + ["0.1"] * len(REQUIRED_CHANNELS) for k in range(5)]
    path = tmp_path / name
    path.write_text("\n".join([",".join(header)] + [",".join(r) for r in rows]) + "\n")
    names = [h.split(" [")[0] for h in header[1:]]
    side = {"format": "panto-rig-dataset", "version": 1,
            "channels": [{"name": n, "unit": (units or {}).get(n, STANDARD_CHANNELS[n].unit
                                                                if n in STANDARD_CHANNELS
                                                                else "1")} for n in names],
            "metadata": {"sample_rate": 500.0, "source": "rig", "status": "complete"}}
    (tmp_path / (name + ".json")).write_text(json.dumps(side))
    return path


def spoil(column, row, value):
    def change(header, rows):
        rows[row][column] = value
    return change


CASES = {
    "missing channel": (lambda h, r: [h.pop(4)] + [x.pop(4) for x in r],
                        r"required channel\(s\) \['force'\] missing"),
    "duplicated channel": (lambda h, r: h.__setitem__(2, "force [N]"),
                           r"channel\(s\) \['force'\] duplicated"),
    "non-monotonic time": (spoil(0, 3, "0.001"), r"time is not strictly increasing at row 3"),
    "non-finite time": (spoil(0, 2, "inf"), r"time is not finite at row 2"),
    "NaN not allowed": (spoil(4, 1, ""), r"channel 'force': NaN at row 1"),
    "wrong unit": (lambda h, r: h.__setitem__(4, "force [kN]"),
                   r"channel 'force': unit 'kN' in the header but 'N'"),
    "mismatched lengths": (lambda h, r: r[2].pop(), r"row 3 has 7 fields, the header has 8"),
    "not a number": (spoil(5, 4, "abc"), r"channel 'pressure_demand': row 5 is not a number"),
}


@pytest.mark.parametrize("case", CASES, ids=list(CASES))
def test_malformed_csv_is_refused_with_a_clear_message(tmp_path, case):
    change, message = CASES[case]
    header = ["time [s]"] + [f"{n} [{STANDARD_CHANNELS[n].unit}]" for n in REQUIRED_CHANNELS]
    rows = [[repr(k * 0.002)] + ["0.1"] * len(REQUIRED_CHANNELS) for k in range(5)]
    change(header, rows)
    path = minimal_csv(tmp_path, header, rows)
    with pytest.raises(DatasetError, match=message) as caught:
        read_dataset(path)
    assert str(path) in str(caught.value)


def test_units_wrong_or_unknown_are_refused_or_converted_on_request(tmp_path):
    header = ["time [s]"] + [f"{n} [{'kN' if n == 'force' else STANDARD_CHANNELS[n].unit}]"
                             for n in REQUIRED_CHANNELS]
    path = minimal_csv(tmp_path, header, units={"force": "kN"})
    with pytest.raises(DatasetError, match=r"'force': unit 'kN', expected 'N' .*convert_units"):
        read_dataset(path)
    assert np.all(read_dataset(path, convert_units=True)["force"] == 100.0)  # 0.1 kN
    header[4] = "force [furlong]"
    path = minimal_csv(tmp_path, header, units={"force": "furlong"}, name="odd.csv")
    with pytest.raises(DatasetError, match=r"'force': unknown unit 'furlong'"):
        read_dataset(path)
    header[4] = "force [bar]"
    path = minimal_csv(tmp_path, header, units={"force": "bar"}, name="odd2.csv")
    with pytest.raises(DatasetError, match=r"'force': unit 'bar' is not a unit of 'N'"):
        read_dataset(path, convert_units=True)


def test_malformed_mat_and_parquet_are_refused(tmp_path):
    dataset = make_dataset()
    mat = dataset.write(tmp_path / "run.mat")
    data = loadmat(mat)
    data["force"] = data["force"][:-1]  # mismatched lengths
    savemat(tmp_path / "short.mat", {k: v for k, v in data.items() if not k.startswith("__")})
    with pytest.raises(DatasetError, match=r"short\.mat: channel 'force': 1499 samples, time "
                                           r"has 1500"):
        read_dataset(tmp_path / "short.mat")
    import pyarrow as pa
    import pyarrow.parquet as pq
    table = pq.read_table(dataset.write(tmp_path / "run.parquet"))
    doubled = pa.Table.from_arrays(table.columns + [table.column("force")],
                                   schema=table.schema.append(table.schema.field("force")))
    pq.write_table(doubled, tmp_path / "twice.parquet")
    with pytest.raises(DatasetError, match=r"twice\.parquet: channel\(s\) \['force'\] dup"):
        read_dataset(tmp_path / "twice.parquet")


def test_metadata_is_checked():
    with pytest.raises(DatasetError, match="source = 'bench'"):
        RunMetadata(sample_rate=500.0, source="bench")
    with pytest.raises(DatasetError, match="status = 'failed'"):
        RunMetadata(sample_rate=500.0, source="rig", status="failed")


# --- recorder ---------------------------------------------------------------------------------

def row(k):
    return [0.1 + k * 1e-5, 0.1, 0.1 + k * 1e-6, 80.0 + k % 7, 4.0, 4.0, float(k % 2)]


def metadata():
    return RunMetadata(sample_rate=500.0, source="emulator", seed=3)


def test_recorder_writes_a_complete_run_and_copies(tmp_path):
    folder = new_run_folder(tmp_path)
    with Recorder(folder, channels=REQUIRED_CHANNELS, metadata=metadata()) as recorder:
        for k in range(1234):
            recorder.append(k / 500.0, row(k))
        recorder.finish(formats=("parquet", "mat"))
    runs = [read_dataset(folder / f"run.{s}") for s in ("csv", "parquet", "mat")]
    assert all(len(r) == 1234 and r.metadata.status == "complete" for r in runs)
    assert all(np.array_equal(r["motor_position"], runs[0]["motor_position"]) for r in runs)
    assert np.array_equal(runs[0]["force"], [80.0 + k % 7 for k in range(1234)])
    assert new_run_folder(tmp_path).name == "run_0002"


def test_exception_mid_run_leaves_flushed_rows_and_status_aborted(tmp_path):
    folder = tmp_path / "run"
    with pytest.raises(RuntimeError, match="following error"):
        with Recorder(folder, channels=REQUIRED_CHANNELS, metadata=metadata(),
                      buffer_rows=500) as recorder:
            for k in range(1700):
                recorder.append(k / 500.0, row(k))
            raise RuntimeError("drive error 0x0B following error")
    run = read_dataset(folder)
    assert len(run) == 1700 and run.time[-1] == 1699 / 500.0
    assert run.metadata.status == ("aborted: RuntimeError: drive error 0x0B following error "
                                   "at t = 3.398 s")
    assert any("aborted" in w for w in run.warnings)


def test_crash_loses_at_most_the_last_buffer_and_a_torn_line_is_reported(tmp_path):
    folder = tmp_path / "crashed"
    script = textwrap.dedent(f"""
        import os
        from panto.rig.dataset import RunMetadata, REQUIRED_CHANNELS
        from panto.rig.recorder import Recorder
        rec = Recorder({str(folder)!r}, channels=REQUIRED_CHANNELS,
                       metadata=RunMetadata(sample_rate=500.0, source="emulator"),
                       buffer_rows=500)
        for k in range(1234):
            rec.append(k / 500.0, [0.1, 0.1, 0.1, 80.0, 4.0, 4.0, 1.0])
        os._exit(1)  # a crash: no flush, no finish
    """)
    done = subprocess.run([sys.executable, "-c", script], cwd=Path(__file__).parents[1])
    assert done.returncode == 1
    run = read_dataset(folder)
    assert len(run) == 1000 and run.metadata.status == "running"
    assert any("without being finished" in w for w in run.warnings)
    with open(folder / "run.csv", "a") as stream:
        stream.write("2.0,0.1,0.1,0.1,8")  # a row cut by the crash
    torn = read_dataset(folder)
    assert len(torn) == 1000 and any("torn" in w for w in torn.warnings)


def test_recorder_never_overwrites_and_refuses_bad_rows(tmp_path):
    folder = tmp_path / "run"
    with Recorder(folder, channels=REQUIRED_CHANNELS, metadata=metadata()) as recorder:
        recorder.append(0.0, row(0))
        with pytest.raises(DatasetError, match="'force': NaN"):
            recorder.append(0.002, [0.1, 0.1, 0.1, float("nan"), 4.0, 4.0, 0.0])
        with pytest.raises(DatasetError, match="not finite and after"):
            recorder.append(0.0, row(1))
        recorder.append(0.002, row(1))
        recorder.finish()
    before = (folder / "run.csv").read_bytes()
    with pytest.raises(FileExistsError, match="never overwrites"):
        Recorder(folder, channels=REQUIRED_CHANNELS, metadata=metadata())
    assert (folder / "run.csv").read_bytes() == before and len(read_dataset(folder)) == 2
    with pytest.raises(DatasetError, match=r"required channel\(s\) \['led'\] missing"):
        Recorder(tmp_path / "other", channels=REQUIRED_CHANNELS[:-1], metadata=metadata())


def test_background_writer_gives_the_same_file(tmp_path):
    texts = []
    for background in (False, True):
        folder = tmp_path / f"run_{background}"
        recorder = Recorder(folder, channels=REQUIRED_CHANNELS, metadata=metadata(),
                            buffer_rows=100, background=background)
        for k in range(1050):
            recorder.append(k / 500.0, row(k))
        recorder.finish()
        assert recorder.rows_written == 1050
        texts.append((folder / "run.csv").read_text())
    assert texts[0] == texts[1]
