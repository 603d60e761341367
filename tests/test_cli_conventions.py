"""The command line's conventions (issue 21): ``--version`` and ``panto.__version__`` from the
package metadata, ``python -m panto``, exit codes by class documented in ``--help``, help text on
every option, ``-v``/``-q`` after the subcommand too, Ctrl-C and internal errors in one line,
a closed pipe ending quietly.
"""
from __future__ import annotations

import importlib.metadata
import subprocess
import sys

import numpy as np
import pytest

import panto
from panto import cli
from panto.cli import EXIT_CODES, main, walk_parsers


def test_version_comes_from_the_package_metadata(capsys):
    assert panto.__version__ == importlib.metadata.version("panto")
    assert main(["--version"]) == 0
    assert capsys.readouterr().out.strip() == f"panto {panto.__version__}"


def test_python_dash_m_panto_is_the_same_command_line():
    done = subprocess.run([sys.executable, "-m", "panto", "--version"], capture_output=True,
                          text=True, timeout=120)
    assert done.returncode == 0 and done.stdout.strip() == f"panto {panto.__version__}"


def test_help_documents_every_exit_code(capsys):
    assert main(["--help"]) == 0
    printed = capsys.readouterr().out
    assert len(set(EXIT_CODES)) == len(EXIT_CODES) >= 5
    for code, meaning in EXIT_CODES.items():
        assert f"{code:>3}  {meaning}" in printed


def test_every_option_and_argument_has_help_text():
    parser, _ = cli._parser()
    missing = [f"{p.prog} {a.option_strings or a.dest}" for p in walk_parsers(parser)
               for a in p._actions if not (a.help or "").strip()]
    assert not missing, missing


def _fake_command(monkeypatch, body):
    """Make ``panto parameters`` run `body(args)` instead of writing a parameter file."""
    monkeypatch.setattr(cli, "run_parameters", body)


@pytest.mark.parametrize("flags", [["-q"], ["--quiet"]])
def test_quiet_after_the_subcommand_silences_progress_not_results(flags, monkeypatch, capsys):
    from panto.console import progress, say

    def body(args):
        progress("step 1 of 3")
        say("result 42")
        return 0

    _fake_command(monkeypatch, body)
    assert main(["parameters", "--out", "x.json"]) == 0
    assert "step 1 of 3" in capsys.readouterr().err
    assert main(["parameters", "--out", "x.json", *flags]) == 0
    printed = capsys.readouterr()
    assert "result 42" in printed.out and "step 1 of 3" not in printed.err
    assert main(["-q", "parameters", "--out", "x.json", "-v"]) == 0  # both places at once
    assert "step 1 of 3" not in capsys.readouterr().err


def test_an_internal_error_is_one_line_with_code_3_and_the_traceback_on_request(monkeypatch,
                                                                                capsys):
    _fake_command(monkeypatch, lambda args: 1 / 0)
    assert main(["parameters", "--out", "x.json"]) == 3
    error = capsys.readouterr().err
    assert len(error.strip().splitlines()) == 1 and "ZeroDivisionError" in error
    assert "Traceback" not in error and "-v" in error
    assert main(["parameters", "--out", "x.json", "-v"]) == 3
    assert "Traceback" in capsys.readouterr().err


def test_ctrl_c_keeps_what_was_recorded_and_exits_4(monkeypatch, tmp_path, capsys):
    """A recording interrupted by Ctrl-C: one line, code 4, and the rows up to it are on disk,
    marked aborted."""
    from panto.rig.dataset import RunMetadata, read_dataset
    from panto.rig.recorder import Recorder

    def body(args):
        with Recorder(tmp_path / "run", channels=["force"], units={"force": "N"}, required=(),
                      metadata=RunMetadata(sample_rate=100.0, source="emulator")) as recorder:
            for k in range(50):
                recorder.append(k / 100.0, [float(k)])
            raise KeyboardInterrupt

    _fake_command(monkeypatch, body)
    assert main(["parameters", "--out", "x.json"]) == 4
    error = capsys.readouterr().err.strip()
    assert len(error.splitlines()) == 1 and "Ctrl-C" in error and "Traceback" not in error
    kept = read_dataset(tmp_path / "run", required=())
    assert np.array_equal(kept["force"], np.arange(50.0))
    assert kept.metadata.status.startswith("aborted")


def test_a_closed_pipe_ends_quietly(tmp_path):
    """``panto rig check RUN | head -0``: no traceback, the documented code."""
    from panto.rig.dataset import Dataset, RunMetadata

    t = np.arange(2000) / 500.0
    path = Dataset(t, {f"c{k}": np.sin(t * k) for k in range(300)},
                   {f"c{k}": "1" for k in range(300)},
                   RunMetadata(sample_rate=500.0, source="emulator")).write(tmp_path / "r.csv")
    child = subprocess.Popen([sys.executable, "-m", "panto", "rig", "check", str(path),
                              "--any-channels"], stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    child.stdout.close()  # the reader is gone before the first line is written
    error = child.stderr.read().decode()
    assert child.wait(timeout=120) == 141 and error == ""


def test_rig_limits_are_printed_with_units_and_no_python_reprs():
    import numpy as np

    from panto.identification.design.constraints import RigInputConstraints

    text = RigInputConstraints.from_rig(minimum_contact_force=np.float64(20.0)).describe()
    assert "np." not in text and "float64" not in text and "(" in text
    for piece in ("m/s", "bar", "minimum contact force 20 N", "sample period"):
        assert piece in text, piece


def _chatty(args):
    """A command that reports progress, a library's debug record, a third party's, a result."""
    import logging

    from panto.console import progress, say

    progress("step 1 of 3")
    progress("diagnose: WARNING: nothing withheld")
    logging.getLogger("panto.rig.session").debug("detail record")
    logging.getLogger("somelibrary").debug("library noise")
    say("result 42")
    return 0


def test_results_on_stdout_progress_on_stderr_and_v_deepens(monkeypatch, capsys):
    import re

    _fake_command(monkeypatch, _chatty)
    assert main(["parameters", "--out", "x.json"]) == 0
    printed = capsys.readouterr()
    assert printed.out == "result 42\n"
    assert "step 1 of 3" in printed.err and "WARNING: nothing withheld" in printed.err
    assert "detail record" not in printed.err and "library noise" not in printed.err
    assert main(["parameters", "--out", "x.json", "-v"]) == 0
    printed = capsys.readouterr()
    assert printed.out == "result 42\n" and "detail record" in printed.err
    assert re.search(r"^\d\d:\d\d:\d\d step 1 of 3$", printed.err, re.MULTILINE)
    assert "library noise" not in printed.err
    for argv in (["-v", "parameters", "--out", "x.json", "-v"], ["parameters", "--out", "x.json",
                                                                  "-vv"]):
        assert main(argv) == 0  # -v before and after the subcommand add up to -vv
        printed = capsys.readouterr()
        assert printed.out == "result 42\n" and "library noise" in printed.err
    assert main(["parameters", "--out", "x.json", "-q"]) == 0  # warnings survive --quiet
    printed = capsys.readouterr()
    assert "WARNING: nothing withheld" in printed.err and "step 1 of 3" not in printed.err


def test_counted_progress_draws_a_bar_on_a_terminal_and_lines_elsewhere(monkeypatch, capsys):
    from panto import console

    def body(args):
        for k in range(1, 21):
            console.progress(f"tracked {k}/20 frames")
        console.say("result")
        return 0

    _fake_command(monkeypatch, body)
    assert main(["parameters", "--out", "x.json"]) == 0  # not a terminal: every line
    printed = capsys.readouterr()
    assert printed.out == "result\n"
    assert all(f"tracked {k}/20 frames\n" in printed.err for k in range(1, 21))
    monkeypatch.setattr(console, "_terminal", lambda: True)
    assert main(["parameters", "--out", "x.json"]) == 0
    printed = capsys.readouterr()
    assert printed.out == "result\n"
    assert "%|" in printed.err and "\r" in printed.err  # tqdm's bar, redrawn in place
    assert "tracked 7/20 frames\n" not in printed.err  # no scrolling line per step
    assert printed.err.rstrip().endswith("tracked 20/20 frames")  # the last line stays
    assert main(["parameters", "--out", "x.json", "-v"]) == 0  # -v: lines, no bar
    printed = capsys.readouterr()
    assert "%|" not in printed.err and "tracked 7/20 frames\n" in printed.err


def test_json_dash_writes_the_document_alone_to_stdout(tmp_path, capsys):
    import json

    assert main(["linearise", "--json", "-"]) == 0
    printed = capsys.readouterr()
    document = json.loads(printed.out)  # nothing but the JSON document
    assert "modes [Hz]" in printed.err and "modes" not in printed.out
    assert main(["linearise", "--json", str(tmp_path / "l.json")]) == 0
    assert json.loads((tmp_path / "l.json").read_text()) == document
    assert f"wrote {tmp_path / 'l.json'}" in capsys.readouterr().out


@pytest.mark.parametrize("error, code, fragment", [
    (ValueError("data.csv: column 'force': row 3 is not a number"), 65, "row 3"),
    (FileNotFoundError("data.csv: no such file"), 65, "no such file"),
    (KeyError("F_c"), 3, "internal error: KeyError"),
    (IndexError("index 7 is out of bounds"), 3, "internal error: IndexError"),
    (NotImplementedError("later"), 3, "internal error: NotImplementedError"),
], ids=["value", "missing-file", "key-bug", "index-bug", "not-implemented"])
def test_exit_codes_by_class(error, code, fragment, monkeypatch, capsys):
    def body(args):
        raise error

    _fake_command(monkeypatch, body)
    assert main(["parameters", "--out", "x.json"]) == code
    printed = capsys.readouterr().err.strip()
    assert len(printed.splitlines()) == 1 and fragment in printed


def test_a_library_key_error_is_an_internal_error_not_bad_input(monkeypatch, capsys):
    """A dict lookup that fails deep in the library is a bug (3), whatever its message."""
    from panto.data_options import UsageError

    _fake_command(monkeypatch, lambda args: {"eta": 1.0}["p"])
    assert main(["parameters", "--out", "x.json"]) == 3
    assert "internal error: KeyError: 'p'" in capsys.readouterr().err

    def body(args):
        raise UsageError("--repeat needs --closed-loop")

    _fake_command(monkeypatch, body)
    assert main(["parameters", "--out", "x.json"]) == 2
    assert "--repeat needs --closed-loop (see panto parameters --help)" in capsys.readouterr().err
