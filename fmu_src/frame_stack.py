"""Keep CPython 3.11/3.12 from mapping and unmapping a frame-stack chunk on every call of a hot
loop.

CPython 3.11 keeps its Python frames on a stack of 16 KiB chunks. When a call needs more room
than the current chunk has, a new chunk is mapped (``mmap``); when the frame at its base returns,
the chunk is unmapped (``munmap``). A loop that calls a function whose frame falls exactly on a
chunk boundary therefore maps and unmaps 16 KiB on every call (CPython issue gh-142183, "Calls
across stack chunks perform badly"; fixed by caching one chunk in 3.13 and 3.14 patch releases of
March 2026, not in 3.11 or 3.12). Where the boundary falls depends on how deep the caller's stack
is, so one diagnosis can run clean from the command line and thrash under pytest. Measured here
(session 52): one diagnosis test made 250 000 ``mmap``/``munmap`` pairs, 2.0 s of its 20 s as
system time; with :func:`keep_stack_chunks` 0.17 s.

:func:`keep_stack_chunks` installs an arena allocator (``PyObject_SetArenaAllocator``, the
documented hook for the memory CPython's small-object allocator and frame stack take from the
system) that keeps up to :data:`KEPT` freed blocks of at most :data:`LARGEST` bytes (frame-stack
chunks: the small-object allocator's arenas are larger and always go back) and hands them out
again for a request of the same size; every other request goes to the allocator it replaces
(CPython's ``mmap``/``munmap``). The kept blocks are guarded by a lock of their own (CPython may
free a thread state's frame stack without the GIL), reset in a forked child. The blocks hold
frames, never results: values are unchanged. It is a C kernel of :mod:`panto.fmu_src.c_kernels`
(built on first use, cached); without a compiler, on another Python version, or with
``PANTO_KEEP_STACK_CHUNKS=0`` nothing is installed and everything runs as before, slower where a
loop thrashes.

It changes the whole process's allocator and cannot be taken back, so the library never installs
it on its own: the programs do (the ``panto`` command line, the diagnosis' worker processes, the
benchmark scripts, the tests' conftest). A program calling :func:`~panto.identification.diagnosis.pipeline.diagnose`
or :func:`~panto.identification.estimation.global_fit.fit_global` itself may call
:func:`keep_stack_chunks` first.
"""
from __future__ import annotations

import ctypes
import sys
import threading

from panto.fmu_src import c_kernels

#: Environment variable: ``0`` leaves CPython's arena allocator as it is.
SWITCH_VARIABLE = "PANTO_KEEP_STACK_CHUNKS"
#: Freed blocks kept for reuse at most (frame-stack chunks of 16 KiB, larger for a huge frame:
#: at most 32 x 64 KiB = 2 MiB kept).
KEPT = 32
#: Largest block kept [bytes] (the small-object allocator's arenas, 256 KiB or 1 MiB, always
#: go back).
LARGEST = 65536

SOURCE = f"""
#include <pthread.h>
#include <stddef.h>

typedef struct {{
    void *ctx;
    void *(*alloc)(void *ctx, size_t size);
    void (*free)(void *ctx, void *ptr, size_t size);
}} Arena;

extern void PyObject_GetArenaAllocator(Arena *allocator);
extern void PyObject_SetArenaAllocator(Arena *allocator);

static Arena previous;
static void *kept[{KEPT}];
static size_t kept_size[{KEPT}];
static int count, installed;
/* CPython allocates arenas with the GIL held, but may free a thread state's frame stack without
   it (PyThreadState_Delete): the kept blocks are guarded by their own lock. */
static pthread_mutex_t lock = PTHREAD_MUTEX_INITIALIZER;

static void *take(void *ctx, size_t size) {{
    void *block = NULL;
    pthread_mutex_lock(&lock);
    for (int i = count - 1; i >= 0; --i) {{
        if (kept_size[i] == size) {{
            block = kept[i];
            --count;
            kept[i] = kept[count];
            kept_size[i] = kept_size[count];
            break;
        }}
    }}
    pthread_mutex_unlock(&lock);
    return block != NULL ? block : previous.alloc(previous.ctx, size);
}}

static void give(void *ctx, void *block, size_t size) {{
    int keep = 0;
    pthread_mutex_lock(&lock);
    if (size <= {LARGEST} && count < {KEPT}) {{
        kept[count] = block;
        kept_size[count] = size;
        ++count;
        keep = 1;
    }}
    pthread_mutex_unlock(&lock);
    if (!keep)
        previous.free(previous.ctx, block, size);
}}

/* A forked child starts with the lock free whatever another thread of its parent held. */
static void reset_lock(void) {{
    pthread_mutex_init(&lock, NULL);
}}

/* Called with the GIL held (ctypes.PYFUNCTYPE), so two threads never install at once. */
int panto_keep_stack_chunks(void) {{
    if (!installed) {{
        Arena current, mine = {{NULL, take, give}};
        PyObject_GetArenaAllocator(&current);
        if (current.alloc != take) {{  /* never wrap itself */
            previous = current;
            pthread_atfork(NULL, NULL, reset_lock);
            PyObject_SetArenaAllocator(&mine);
        }}
        installed = 1;
    }}
    return count;
}}
"""


def _bind(library: ctypes.CDLL):
    """The installer, called with the GIL held (``PYFUNCTYPE``: a plain ctypes call releases it,
    and two threads could then install at once)."""
    library.panto_keep_stack_chunks  # AttributeError: not our library
    return ctypes.PYFUNCTYPE(ctypes.c_int)(("panto_keep_stack_chunks", library))


#: The allocator's library (built on first use into the kernel cache).
KERNEL = c_kernels.Kernel("keep_stack_chunks", SWITCH_VARIABLE, ("-O2", "-pthread"), SOURCE,
                          _bind)

_state = {"installed": False, "tried": False}
_lock = threading.Lock()


def keep_stack_chunks() -> bool:
    """Install the arena allocator in this process (module notes), once; True when it is in
    place. Only on CPython 3.11 and 3.12 (where the chunks are not cached), not under a
    switched-off :data:`SWITCH_VARIABLE`, and only where the library builds (tried once per
    process)."""
    with _lock:
        if _state["installed"] or _state["tried"]:
            return _state["installed"]
        if sys.implementation.name != "cpython" or \
                sys.version_info[:2] not in ((3, 11), (3, 12)) or not KERNEL.enabled():
            return False
        _state["tried"] = True
        install = KERNEL.load()
        if install is None:
            return False
        install()
        _state["installed"] = True
        return True


__all__ = ["keep_stack_chunks", "SWITCH_VARIABLE", "KEPT", "LARGEST"]
