"""The frame-stack chunks kept for reuse (panto.fmu_src.frame_stack): a loop whose calls cross a
chunk boundary no longer maps fresh memory on every call, and computes the same values."""
import os
import subprocess
import sys
import textwrap

import pytest

from panto.fmu_src import frame_stack

#: A loop of calls run at every stack depth from 0 to 399 (so that some depth puts the called
#: frame at the base of a 16 KiB chunk), in a fresh process: the minor page faults it caused
#: (each freshly mapped chunk faults its pages in) and its result.
SCRIPT = textwrap.dedent("""
    import json, resource, sys
    from panto.fmu_src.frame_stack import keep_stack_chunks
    installed = keep_stack_chunks()

    def leaf(x):
        a = b = c = d = e = f = g = h = x * 1.5
        return a + b + c + d + e + f + g + h

    def at_depth(depth, calls):
        if depth:
            return at_depth(depth - 1, calls)
        return sum(leaf(k) for k in range(calls))

    before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
    values = [at_depth(depth, 300) for depth in range(400)]
    faults = resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before
    print(json.dumps({"installed": installed, "faults": faults, "values": values}))
""")


def _run(switch: str) -> dict:
    import json
    env = {**os.environ, frame_stack.SWITCH_VARIABLE: switch}
    done = subprocess.run([sys.executable, "-P", "-c", SCRIPT], env=env, capture_output=True,
                          text=True, timeout=120, check=True)
    return json.loads(done.stdout)


@pytest.mark.skipif(sys.version_info[:2] not in ((3, 11), (3, 12)),
                    reason="CPython 3.11 and 3.12 only map a chunk per boundary call")
def test_a_loop_across_a_chunk_boundary_maps_no_fresh_memory_and_gives_the_same_values():
    plain, kept = _run("0"), _run("1")
    if not kept["installed"]:
        pytest.skip("the allocator's library could not be built (no C compiler)")
    assert plain["installed"] is False
    # without the kept chunks, the boundary depths fault a fresh chunk's touched pages in on every
    # call (300 calls each): some 2 400 faults here; with them, the loop reuses one chunk
    assert plain["faults"] > 1000
    assert kept["faults"] < plain["faults"] / 20
    assert kept["values"] == plain["values"]


def test_switched_off_by_its_variable_nothing_is_installed(monkeypatch):
    monkeypatch.setattr(frame_stack, "_state", {"installed": False, "tried": False})
    monkeypatch.setenv(frame_stack.SWITCH_VARIABLE, "0")
    assert frame_stack.keep_stack_chunks() is False
    assert frame_stack._state["installed"] is False


def test_threads_that_start_and_end_with_it_installed_run_and_compute_right():
    """A smoke test: every thread's frame stack is allocated and freed through the kept blocks
    (320 threads, each recursing to depths 0-294); a block handed out wrongly would crash or
    corrupt the sums. (The threads free their stacks with the GIL held, so this does not
    exercise the allocator's own lock.)"""
    import threading

    def deep(depth: int) -> int:
        return 0 if depth == 0 else 1 + deep(depth - 1)

    sums: dict[int, int] = {}

    def work(k: int) -> None:
        sums[k] = sum(deep(d) for d in range(0, 300, 7))

    for round_ in range(20):
        threads = [threading.Thread(target=work, args=(16 * round_ + k,)) for k in range(16)]
        for thread in threads:
            thread.start()
        for thread in threads:
            thread.join()
    assert sums == {k: sum(range(0, 300, 7)) for k in range(320)}
