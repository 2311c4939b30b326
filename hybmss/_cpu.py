"""What the kernels need of the CPU that Numba does not give: atomic integers, a spinning
barrier, and the flush-to-zero mode of the floating-point unit.

**Barrier.**  The threaded explicit kernel (:mod:`hybmss._stencil_gen`) runs all its steps on
its threads at once: each thread advances its own node range and waits for the others once per
step at :func:`barrier`.  The three atomic operations are LLVM's (``atomicrmw add``, ``load
atomic acquire``, ``store atomic release``) on one element of an int64 array, so the compiler
neither caches the shared counters in registers nor moves the state's loads and stores across
them.  State of a barrier: an int64 array ``S`` of :data:`SLOTS` entries, zero at the start:
``S[COUNT]`` threads arrived in the current round, ``S[ROUND]`` rounds completed, ``S[ABORT]``
set when a thread gave up waiting (the others leave at their next barrier), ``S[MESSAGE]`` a
value one thread publishes to all (the diverged node of a check).

**Subnormals.**  The front of a wave leaves, ahead of itself, displacements that decay by orders
of magnitude per cell; in float32 they reach the subnormal range (below 1.2e-38) within a few
dozen cells, and arithmetic on subnormals is many times slower on x86 (a 30³ cube in float32
ran 4× slower than in float64 for that alone).  :func:`flush_subnormals` sets the MXCSR bits
FTZ and DAZ (results and inputs below the normal range are zero) for the calling thread and
returns the previous mode for :func:`restore_fp_mode`.  Values that small carry no physics (a
displacement of 1e-38 m); every thread of a kernel sets the same mode, so threads still agree
bit for bit.
"""

from __future__ import annotations

from llvmlite import ir
from numba import njit, types
from numba.core import cgutils
from numba.extending import intrinsic

COUNT, ROUND, ABORT, MESSAGE = 0, 1, 2, 3
SLOTS = 8  # one 64-byte line
SPINS_BEFORE_YIELD = 1 << 10
"""Polls (``pause``, tens of ns each) before a waiting thread yields its core at every poll: on
an idle machine the others arrive within that; on a busy one a thread that only spins would
keep a descheduled partner off its core for a whole time slice (milliseconds) per step."""
SPIN_LIMIT = 1 << 22
"""Polls of the round counter before a waiting thread gives up (seconds, most of them spent
yielding: the other threads are not running, e.g. one that was never started)."""


def _pointer(context, builder, aryty, ary, idx):
    arr = context.make_array(aryty)(context, builder, ary)
    return cgutils.get_item_pointer(context, builder, aryty, arr, [idx])


@intrinsic
def atomic_add(typingctx, arr, idx, val):
    """``old = arr[idx]; arr[idx] += val; return old`` as one sequentially consistent step."""
    sig = types.int64(arr, types.intp, types.int64)

    def codegen(context, builder, signature, args):
        ptr = _pointer(context, builder, signature.args[0], args[0], args[1])
        return builder.atomic_rmw("add", ptr, args[2], "seq_cst")

    return sig, codegen


@intrinsic
def atomic_load(typingctx, arr, idx):
    """``arr[idx]``, read with acquire ordering (no later access moves before it)."""
    sig = types.int64(arr, types.intp)

    def codegen(context, builder, signature, args):
        ptr = _pointer(context, builder, signature.args[0], args[0], args[1])
        return builder.load_atomic(ptr, "acquire", 8)

    return sig, codegen


@intrinsic
def atomic_store(typingctx, arr, idx, val):
    """``arr[idx] = val`` with release ordering (no earlier access moves after it)."""
    sig = types.void(arr, types.intp, types.int64)

    def codegen(context, builder, signature, args):
        ptr = _pointer(context, builder, signature.args[0], args[0], args[1])
        builder.store_atomic(args[2], ptr, "release", 8)
        return context.get_dummy_value()

    return sig, codegen


@intrinsic
def cpu_relax(typingctx):
    """The x86 ``pause`` hint of a spin-wait loop."""
    sig = types.void()

    def codegen(context, builder, signature, args):
        fn = cgutils.get_or_insert_function(builder.module, ir.FunctionType(ir.VoidType(), []),
                                            "llvm.x86.sse2.pause")
        builder.call(fn, [])
        return context.get_dummy_value()

    return sig, codegen


@intrinsic
def yield_cpu(typingctx):
    """``sched_yield()``: let another runnable thread have this core."""
    sig = types.void()

    def codegen(context, builder, signature, args):
        fn = cgutils.get_or_insert_function(builder.module, ir.FunctionType(ir.IntType(32), []), "sched_yield")
        builder.call(fn, [])
        return context.get_dummy_value()

    return sig, codegen


@njit(cache=True, nogil=True)
def barrier(S, nthreads):
    """Wait until ``nthreads`` threads have called this for the current round.  Returns False
    (and sets ``S[ABORT]``) if the others did not come within :data:`SPIN_LIMIT` polls, or if
    another thread had given up."""
    r = atomic_load(S, ROUND)
    if atomic_add(S, COUNT, 1) == nthreads - 1:
        atomic_store(S, COUNT, 0)
        atomic_add(S, ROUND, 1)  # releases the waiting threads
        return atomic_load(S, ABORT) == 0
    spins = 0
    while atomic_load(S, ROUND) == r:
        if atomic_load(S, ABORT) != 0:
            return False
        spins += 1
        if spins >= SPIN_LIMIT:
            atomic_store(S, ABORT, 1)
            return False
        if spins < SPINS_BEFORE_YIELD:
            cpu_relax()
        else:  # the others are late: they may be waiting for this core
            yield_cpu()
    return atomic_load(S, ABORT) == 0


FTZ_DAZ = 0x8040
"""MXCSR bits 15 (flush to zero) and 6 (denormals are zero)."""


def _mxcsr_call(builder, name, ptr):
    i8p = ir.IntType(8).as_pointer()
    fn = cgutils.get_or_insert_function(builder.module, ir.FunctionType(ir.VoidType(), [i8p]), name)
    builder.call(fn, [builder.bitcast(ptr, i8p)])


@intrinsic
def get_fp_mode(typingctx):
    """The MXCSR register of the calling thread."""
    sig = types.int64()

    def codegen(context, builder, signature, args):
        slot = cgutils.alloca_once(builder, ir.IntType(32))
        _mxcsr_call(builder, "llvm.x86.sse.stmxcsr", slot)
        return builder.zext(builder.load(slot), ir.IntType(64))

    return sig, codegen


@intrinsic
def set_fp_mode(typingctx, mode):
    """Load ``mode`` into the MXCSR register of the calling thread."""
    sig = types.void(types.int64)

    def codegen(context, builder, signature, args):
        slot = cgutils.alloca_once(builder, ir.IntType(32))
        builder.store(builder.trunc(args[0], ir.IntType(32)), slot)
        _mxcsr_call(builder, "llvm.x86.sse.ldmxcsr", slot)
        return context.get_dummy_value()

    return sig, codegen


@njit(cache=True, nogil=True)
def flush_subnormals():
    """Set FTZ and DAZ for the calling thread; returns the previous MXCSR."""
    old = get_fp_mode()
    set_fp_mode(old | FTZ_DAZ)
    return old


@njit(cache=True, nogil=True)
def restore_fp_mode(old):
    set_fp_mode(old)
