"""One march step for four rays at once, in LLVM vector instructions: the inner step of the ray caster's pool
kernel (:func:`locbench.raycast.cast._march_pool`).

numba does not vectorise the march itself: the per-ray state lives in a dozen arrays that LLVM cannot prove
apart, and the step's branches (jump or cell step, x or y boundary, hit, leave) are data-dependent. So the step
is written here, and only here, as a numba intrinsic that emits LLVM IR on 4-wide vectors: each branch of the
step is a select, and the four cells' values are loaded one by one (AVX2 has no byte gather). Each lane's
arithmetic is the IEEE operations written below, in order (no fused multiply-adds: LLVM does not contract without
fast-math flags), so a beam's range does not depend on its lane, on the other beams of the pool or on the field
it marches on (the tests compare these layouts bit for bit, and the ranges with the exact traversal's to
rounding).

State layout (one column per lane, ``W`` lanes, a multiple of 4):

``fstate`` (NF, W) float64
    rows :data:`T` (the beam's parameter, cells), :data:`T0` (where it entered the grid), :data:`GX`, :data:`GY`
    (start, cells), :data:`DX`, :data:`DY` (unit direction), :data:`IX`, :data:`IY` (1 / direction, or a huge
    number for an axis-parallel beam), :data:`AX`, :data:`AY` (exit-boundary offsets: cell (i, j) is left at
    x = j + AX + GX), :data:`BX`, :data:`BY` (entry-boundary offsets), and :data:`RES` (written: the range in m
    of a lane that ended at this step, inf for no hit).
``istate`` (NC, W) int32
    rows :data:`CI`, :data:`CJ` (the cell), :data:`CB` (offset of the beam's plane in ``planes``).

A lane whose :data:`T` is inf is idle: it never reports a hit and ends at every step.

numba's on-disk cache of the kernels that call :data:`step4` is keyed on :mod:`locbench.raycast.cast`'s source alone:
after editing this module, delete the ``*.nbi`` / ``*.nbc`` files under ``bench/raycast/__pycache__``.
"""

from __future__ import annotations

import math
from typing import Any

from llvmlite import ir
from numba import types
from numba.core import cgutils
from numba.extending import intrinsic

#: Rows of the float state ``fstate``.
T, T0, GX, GY, DX, DY, IX, IY, AX, AY, BX, BY, RES = range(13)
NF = 13
#: Rows of the integer state ``istate``.
CI, CJ, CB = range(3)
NC = 3

_F64 = ir.DoubleType()
_I32 = ir.IntType(32)
_I64 = ir.IntType(64)
_V4D = ir.VectorType(_F64, 4)
_V4I = ir.VectorType(_I32, 4)


def _splat(builder: ir.IRBuilder, value: ir.Value, vty: ir.VectorType) -> ir.Value:
    one = builder.insert_element(ir.Constant(vty, ir.Undefined), value, ir.Constant(_I32, 0))
    return builder.shuffle_vector(one, ir.Constant(vty, ir.Undefined), ir.Constant(_V4I, [0, 0, 0, 0]))


def _const(vty: ir.VectorType, x: float) -> ir.Constant:
    return ir.Constant(vty, [x] * 4)


def _step4(
    typingctx: Any,
    fstate: Any,
    istate: Any,
    planes: Any,
    q: Any,
    cols: Any,
    rows: Any,
    t_end: Any,
    t_lim: Any,
    res: Any,
    occupied: Any,
    jump_unit: Any,
    nudge: Any,
) -> Any:
    """One step of lanes ``q .. q + 3``; returns the 4-bit mask of the lanes that ended (bit k: lane q + k).

    Per lane, with ``v`` the value of its cell in ``planes`` (at ``istate[CB] + i * cols + j``): a cell valued
    ``occupied`` is a hit at the cell's entry time ``max(T0, (j + BX) * IX, (i + BY) * IY)``, reported as that
    times ``res`` (m) if it is within ``t_lim`` (cells), else inf. Otherwise the beam jumps to
    ``t + v * jump_unit`` if that leaves the cell by more than ``nudge``, else steps to the next cell across
    the nearer exit boundary; it ends (range inf) when past ``t_end`` or out of the ``rows`` x ``cols`` grid.
    An ended lane keeps its cell (so its next load stays in bounds). The next cell's line is prefetched, so that
    the lane's next visit, a whole sweep of the pool later, finds it in L1.
    """
    # long: a numba intrinsic: the LLVM code generator below must be a closure of its typing function
    sig = types.int64(fstate, istate, planes, q, cols, rows, t_end, t_lim, res, occupied, jump_unit, nudge)

    def codegen(context: Any, builder: ir.IRBuilder, signature: Any, args: Any) -> ir.Value:
        # long: one LLVM function body emitted in order (the four lanes' setup, loop and exit blocks share builders)
        s_arr = context.make_array(signature.args[0])(context, builder, args[0])
        c_arr = context.make_array(signature.args[1])(context, builder, args[1])
        p_arr = context.make_array(signature.args[2])(context, builder, args[2])
        q_v, cols_v, rows_v, t_end_v, t_lim_v, res_v, occ_v, unit_v, nudge_v = args[3:]
        width = builder.extract_value(s_arr.shape, 1)
        mod = builder.module
        floor = cgutils.get_or_insert_function(mod, ir.FunctionType(_V4D, [_V4D]), "llvm.floor.v4f64")
        prefetch = cgutils.get_or_insert_function(
            mod, ir.FunctionType(ir.VoidType(), [ir.IntType(8).as_pointer(), _I32, _I32, _I32]), "llvm.prefetch.p0i8"
        )

        def row_ptr(arr: Any, row: int, vty: ir.VectorType) -> ir.Value:
            offset = builder.add(builder.mul(ir.Constant(_I64, row), width), q_v)
            return builder.bitcast(builder.gep(arr.data, [offset], inbounds=True), vty.as_pointer())

        def load_s(row: int) -> ir.Value:
            return builder.load(row_ptr(s_arr, row, _V4D), align=8)

        def load_c(row: int) -> ir.Value:
            return builder.load(row_ptr(c_arr, row, _V4I), align=4)

        # max and min as compare and select (vmaxpd, vminpd): no NaN reaches them
        def vmax(a: ir.Value, b: ir.Value) -> ir.Value:
            return builder.select(builder.fcmp_ordered(">", a, b), a, b)

        def vmin(a: ir.Value, b: ir.Value) -> ir.Value:
            return builder.select(builder.fcmp_ordered("<", a, b), a, b)

        def cell_index(i: ir.Value, j: ir.Value) -> ir.Value:
            return builder.add(base, builder.add(builder.mul(i, cols4), j))

        def lane(vec: ir.Value, k: int) -> ir.Value:
            return builder.sext(builder.extract_element(vec, ir.Constant(_I32, k)), _I64)

        i = load_c(CI)
        j = load_c(CJ)
        base = load_c(CB)
        cols4 = _splat(builder, builder.trunc(cols_v, _I32), _V4I)
        rows4 = _splat(builder, builder.trunc(rows_v, _I32), _V4I)
        idx = cell_index(i, j)
        v = ir.Constant(_V4I, ir.Undefined)
        for k in range(4):
            byte = builder.load(builder.gep(p_arr.data, [lane(idx, k)], inbounds=True))
            v = builder.insert_element(v, builder.zext(byte, _I32), ir.Constant(_I32, k))
        t = load_s(T)
        ix = load_s(IX)
        iy = load_s(IY)
        dx = load_s(DX)
        dy = load_s(DY)
        fj = builder.sitofp(j, _V4D)
        fi = builder.sitofp(i, _V4D)
        inf4 = _const(_V4D, math.inf)
        hit = builder.and_(
            builder.icmp_signed("==", v, _splat(builder, builder.trunc(occ_v, _I32), _V4I)),
            builder.fcmp_ordered("!=", t, inf4),
        )
        t_in = vmax(
            load_s(T0),
            vmax(builder.fmul(builder.fadd(fj, load_s(BX)), ix), builder.fmul(builder.fadd(fi, load_s(BY)), iy)),
        )
        tx = builder.fmul(builder.fadd(fj, load_s(AX)), ix)
        ty = builder.fmul(builder.fadd(fi, load_s(AY)), iy)
        t_jump = builder.fadd(t, builder.fmul(builder.sitofp(v, _V4D), _splat(builder, unit_v, _V4D)))
        t_min = vmin(tx, ty)
        zero_i = _const(_V4I, 0)
        jump = builder.and_(
            builder.icmp_signed(">", v, zero_i),
            builder.fcmp_ordered(">", t_jump, builder.fadd(t_min, _splat(builder, nudge_v, _V4D))),
        )
        x_first = builder.fcmp_ordered("<=", tx, ty)
        # landing cell of a jump; clamped just outside the grid before the conversion, so that it stays exact
        low = _const(_V4D, -2.0)
        jj = builder.fptosi(
            vmin(
                vmax(builder.call(floor, [builder.fadd(load_s(GX), builder.fmul(t_jump, dx))]), low),
                _splat(builder, builder.sitofp(cols_v, _F64), _V4D),
            ),
            _V4I,
        )
        ij = builder.fptosi(
            vmin(
                vmax(builder.call(floor, [builder.fadd(load_s(GY), builder.fmul(t_jump, dy))]), low),
                _splat(builder, builder.sitofp(rows_v, _F64), _V4D),
            ),
            _V4I,
        )
        t_new = builder.select(jump, t_jump, vmax(t, builder.select(x_first, tx, ty)))
        zero_d = _const(_V4D, 0.0)
        one = _const(_V4I, 1)
        minus_one = _const(_V4I, -1)
        step_j = builder.select(builder.fcmp_ordered(">", dx, zero_d), one, minus_one)
        step_i = builder.select(builder.fcmp_ordered(">", dy, zero_d), one, minus_one)
        j_new = builder.select(jump, jj, builder.select(x_first, builder.add(j, step_j), j))
        i_new = builder.select(jump, ij, builder.select(x_first, i, builder.add(i, step_i)))
        leave = builder.or_(
            builder.fcmp_unordered(">", t_new, _splat(builder, t_end_v, _V4D)),
            builder.or_(
                builder.or_(builder.icmp_signed("<", j_new, zero_i), builder.icmp_signed(">=", j_new, cols4)),
                builder.or_(builder.icmp_signed("<", i_new, zero_i), builder.icmp_signed(">=", i_new, rows4)),
            ),
        )
        done = builder.or_(hit, leave)
        in_range = builder.and_(hit, builder.fcmp_ordered("<=", t_in, _splat(builder, t_lim_v, _V4D)))
        result = builder.select(in_range, builder.fmul(t_in, _splat(builder, res_v, _V4D)), inf4)
        builder.store(result, row_ptr(s_arr, RES, _V4D), align=8)
        builder.store(t_new, row_ptr(s_arr, T, _V4D), align=8)
        i_kept = builder.select(done, i, i_new)
        j_kept = builder.select(done, j, j_new)
        builder.store(i_kept, row_ptr(c_arr, CI, _V4I), align=4)
        builder.store(j_kept, row_ptr(c_arr, CJ, _V4I), align=4)
        nxt = cell_index(i_kept, j_kept)
        for k in range(4):
            address = builder.gep(p_arr.data, [lane(nxt, k)], inbounds=True)
            # read, high locality, data cache
            builder.call(prefetch, [address, ir.Constant(_I32, 0), ir.Constant(_I32, 3), ir.Constant(_I32, 1)])
        return builder.zext(builder.bitcast(done, ir.IntType(4)), _I64)

    return sig, codegen


#: The intrinsic, called from numba code as ``step4(fstate, istate, planes, q, cols, rows, t_end, t_lim, res,
#: occupied, jump_unit, nudge)`` (the typing context is numba's).
step4: Any = intrinsic(_step4)
