"""Eight-wide float64 vectors for numba kernels (one row of an 8-state covariance).

numba compiles element loops over small matrices to scalar code: its SLP vectoriser is off by
default, and for a trip count of 8 the loop vectoriser's runtime checks cost more than they
save.  These intrinsics give the kernels an explicit LLVM ``<8 x double>`` value type
(:data:`f64x8`), so that one row operation of an 8x8 product is one vector instruction on
AVX-512 (two on AVX2, four on SSE2 or NEON; LLVM legalises the width for the machine).

Every operation is a plain IEEE ``fadd``/``fsub``/``fmul``/``fdiv`` per lane with no fast-math
flags (no contraction into FMA, no reassociation), so a kernel written with these computes
bit-for-bit what the same scalar loop computes, on any machine.

Arrays must be C-contiguous float64; offsets are in elements from the start of the data, and
are not bounds-checked (the callers index rows of arrays whose shape they have checked).
"""

from __future__ import annotations

from llvmlite import ir
from numba import types
from numba.extending import intrinsic, models, register_model

#: Lanes per vector.
W = 8

_VT = ir.VectorType(ir.DoubleType(), W)
_I32 = ir.IntType(32)


class F64x8Type(types.Type):
    """numba type of an ``<8 x double>`` value."""

    def __init__(self):
        super().__init__(name="f64x8")


f64x8 = F64x8Type()


@register_model(F64x8Type)
class _F64x8Model(models.PrimitiveModel):
    def __init__(self, dmm, fe_type):
        super().__init__(dmm, fe_type, _VT)


def _check_array(arr):
    return isinstance(arr, types.Array) and arr.dtype == types.float64 and arr.layout == "C"


def _elem_ptr(context, builder, arrty, arr, off):
    ary = context.make_array(arrty)(context, builder, arr)
    return builder.gep(ary.data, [off])


@intrinsic
def vload(typingctx, arr, off):
    """``arr.flat[off:off + 8]`` as a vector."""
    if not (_check_array(arr) and isinstance(off, types.Integer)):
        return None
    sig = f64x8(arr, types.intp)

    def codegen(context, builder, sig, args):
        off = context.cast(builder, args[1], sig.args[1], types.intp)
        p = _elem_ptr(context, builder, sig.args[0], args[0], off)
        return builder.load(builder.bitcast(p, _VT.as_pointer()), align=8)

    return sig, codegen


@intrinsic
def vstore(typingctx, arr, off, v):
    """``arr.flat[off:off + 8] = v``."""
    if not (_check_array(arr) and isinstance(off, types.Integer) and v == f64x8):
        return None
    sig = types.void(arr, types.intp, f64x8)

    def codegen(context, builder, sig, args):
        off = context.cast(builder, args[1], sig.args[1], types.intp)
        p = _elem_ptr(context, builder, sig.args[0], args[0], off)
        builder.store(args[2], builder.bitcast(p, _VT.as_pointer()), align=8)
        return context.get_dummy_value()

    return sig, codegen


@intrinsic
def vcol(typingctx, arr, off, stride):
    """``arr.flat[off + stride * i]`` for ``i = 0..7`` (a column of a row-major matrix)."""
    if not (_check_array(arr) and isinstance(off, types.Integer) and isinstance(stride, types.Integer)):
        return None
    sig = f64x8(arr, types.intp, types.intp)

    def codegen(context, builder, sig, args):
        off = context.cast(builder, args[1], sig.args[1], types.intp)
        stride = context.cast(builder, args[2], sig.args[2], types.intp)
        ary = context.make_array(sig.args[0])(context, builder, args[0])
        v = ir.Constant(_VT, ir.Undefined)
        for i in range(W):
            idx = builder.add(off, builder.mul(stride, ir.Constant(off.type, i)))
            x = builder.load(builder.gep(ary.data, [idx]), align=8)
            v = builder.insert_element(v, x, ir.Constant(_I32, i))
        return v

    return sig, codegen


@intrinsic
def vsplat(typingctx, x):
    """The scalar ``x`` in every lane."""
    if not isinstance(x, types.Float):
        return None
    sig = f64x8(types.float64)

    def codegen(context, builder, sig, args):
        v = builder.insert_element(ir.Constant(_VT, ir.Undefined), args[0], ir.Constant(_I32, 0))
        return builder.shuffle_vector(v, ir.Constant(_VT, ir.Undefined), ir.Constant(ir.VectorType(_I32, W), [0] * W))

    return sig, codegen


def _binop(op, doc):
    @intrinsic
    def fn(typingctx, a, b):
        if not (a == f64x8 and b == f64x8):
            return None
        sig = f64x8(f64x8, f64x8)

        def codegen(context, builder, sig, args):
            return getattr(builder, op)(args[0], args[1])

        return sig, codegen

    fn.__doc__ = doc
    return fn


vadd = _binop("fadd", "Lane-wise ``a + b``.")
vsub = _binop("fsub", "Lane-wise ``a - b``.")
vmul = _binop("fmul", "Lane-wise ``a * b``.")
vdiv = _binop("fdiv", "Lane-wise ``a / b``.")


@intrinsic
def vget(typingctx, v, i):
    """Lane ``i`` of ``v``."""
    if not (v == f64x8 and isinstance(i, types.Integer)):
        return None
    sig = types.float64(f64x8, types.intp)

    def codegen(context, builder, sig, args):
        i = context.cast(builder, args[1], sig.args[1], types.intp)
        return builder.extract_element(args[0], i)

    return sig, codegen


@intrinsic
def vset(typingctx, v, i, x):
    """``v`` with lane ``i`` replaced by ``x``."""
    if not (v == f64x8 and isinstance(i, types.Integer) and isinstance(x, types.Float)):
        return None
    sig = f64x8(f64x8, types.intp, types.float64)

    def codegen(context, builder, sig, args):
        i = context.cast(builder, args[1], sig.args[1], types.intp)
        return builder.insert_element(args[0], args[2], i)

    return sig, codegen
