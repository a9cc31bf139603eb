"""Float64 vectors of up to 8 lanes for numba kernels (rows of small covariance matrices).

numba compiles element loops over small matrices to scalar code: its SLP vectoriser is off by
default, and for a trip count of 8 the loop vectoriser's runtime checks cost more than they
save.  These intrinsics give the kernels explicit LLVM ``<w x double>`` value types
(:func:`f64x`, ``w <= 8``), so that one row operation of an 8x8 product is one vector
instruction on AVX-512 (two on AVX2, four on SSE2 or NEON; LLVM legalises the width for the
machine); a 14-wide row is an 8-lane and a 6-lane vector.  Widths are literal integer arguments
(``vload(a, off, 8)``).

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

#: Most lanes per vector (one AVX-512 register of float64).
W = 8

_I32 = ir.IntType(32)


class F64xNType(types.Type):
    """numba type of an ``<w x double>`` value, ``1 <= w <= 8``."""

    def __init__(self, width):
        self.width = width
        super().__init__(name=f"f64x{width}")


_TYPES = {w: F64xNType(w) for w in range(1, W + 1)}


def f64x(width: int) -> F64xNType:
    """The vector type with ``width`` lanes."""
    return _TYPES[width]


@register_model(F64xNType)
class _F64xNModel(models.PrimitiveModel):
    def __init__(self, dmm, fe_type):
        super().__init__(dmm, fe_type, ir.VectorType(ir.DoubleType(), fe_type.width))


def _check_array(arr):
    return isinstance(arr, types.Array) and arr.dtype == types.float64 and arr.layout == "C"


def _width(w):
    """The lane count of a literal-integer argument, or None."""
    if isinstance(w, types.IntegerLiteral) and 1 <= w.literal_value <= W:
        return w.literal_value
    return None


_F64 = ir.DoubleType()


def _gep(builder, ptr, idx):
    """``&ptr[idx]`` for a ``double*``; element type given explicitly (opaque pointers)."""
    try:
        return builder.gep(ptr, [idx], source_etype=_F64)
    except TypeError:  # an llvmlite from before opaque pointers: typed pointers only
        return builder.gep(ptr, [idx])


def _load(builder, ptr, ty):
    try:
        return builder.load(ptr, align=8, typ=ty)
    except TypeError:  # an llvmlite from before opaque pointers
        return builder.load(ptr, align=8)


def _elem_ptr(context, builder, arrty, arr, off):
    ary = context.make_array(arrty)(context, builder, arr)
    return _gep(builder, ary.data, off)


@intrinsic(prefer_literal=True)
def vload(typingctx, arr, off, w):
    """``arr.flat[off:off + w]`` as a vector (``w`` a literal integer)."""
    width = _width(w)
    if not (_check_array(arr) and isinstance(off, types.Integer) and width):
        return None
    vt = f64x(width)
    sig = vt(arr, types.intp, w)

    def codegen(context, builder, sig, args):
        off = context.cast(builder, args[1], sig.args[1], types.intp)
        p = _elem_ptr(context, builder, sig.args[0], args[0], off)
        lt = context.get_value_type(vt)
        return _load(builder, builder.bitcast(p, lt.as_pointer()), lt)

    return sig, codegen


@intrinsic
def vstore(typingctx, arr, off, v):
    """``arr.flat[off:off + w] = v`` (``w`` lanes of ``v``)."""
    if not (_check_array(arr) and isinstance(off, types.Integer) and isinstance(v, F64xNType)):
        return None
    sig = types.void(arr, types.intp, v)

    def codegen(context, builder, sig, args):
        off = context.cast(builder, args[1], sig.args[1], types.intp)
        p = _elem_ptr(context, builder, sig.args[0], args[0], off)
        builder.store(args[2], builder.bitcast(p, args[2].type.as_pointer()), align=8)
        return context.get_dummy_value()

    return sig, codegen


@intrinsic(prefer_literal=True)
def vcol(typingctx, arr, off, stride, w):
    """``arr.flat[off + stride * i]`` for ``i = 0..w-1`` (part of a column of a row-major matrix)."""
    width = _width(w)
    if not (_check_array(arr) and isinstance(off, types.Integer) and isinstance(stride, types.Integer) and width):
        return None
    vt = f64x(width)
    sig = vt(arr, types.intp, types.intp, w)

    def codegen(context, builder, sig, args):
        off = context.cast(builder, args[1], sig.args[1], types.intp)
        stride = context.cast(builder, args[2], sig.args[2], types.intp)
        ary = context.make_array(sig.args[0])(context, builder, args[0])
        v = ir.Constant(context.get_value_type(vt), ir.Undefined)
        for i in range(width):
            idx = builder.add(off, builder.mul(stride, ir.Constant(off.type, i)))
            x = _load(builder, _gep(builder, ary.data, idx), _F64)
            v = builder.insert_element(v, x, ir.Constant(_I32, i))
        return v

    return sig, codegen


@intrinsic(prefer_literal=True)
def vsplat(typingctx, x, w):
    """The scalar ``x`` in each of ``w`` lanes (``w`` a literal integer)."""
    width = _width(w)
    if not (isinstance(x, types.Float) and width):
        return None
    vt = f64x(width)
    sig = vt(types.float64, w)

    def codegen(context, builder, sig, args):
        lt = context.get_value_type(vt)
        v = builder.insert_element(ir.Constant(lt, ir.Undefined), args[0], ir.Constant(_I32, 0))
        mask = ir.Constant(ir.VectorType(_I32, width), [0] * width)
        return builder.shuffle_vector(v, ir.Constant(lt, ir.Undefined), mask)

    return sig, codegen


def _binop(op, doc):
    @intrinsic
    def fn(typingctx, a, b):
        if not (isinstance(a, F64xNType) and a == b):
            return None
        sig = a(a, b)

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
    if not (isinstance(v, F64xNType) and isinstance(i, types.Integer)):
        return None
    sig = types.float64(v, types.intp)

    def codegen(context, builder, sig, args):
        i = context.cast(builder, args[1], sig.args[1], types.intp)
        return builder.extract_element(args[0], i)

    return sig, codegen


@intrinsic
def vset(typingctx, v, i, x):
    """``v`` with lane ``i`` replaced by ``x``."""
    if not (isinstance(v, F64xNType) and isinstance(i, types.Integer) and isinstance(x, types.Float)):
        return None
    sig = v(v, types.intp, types.float64)

    def codegen(context, builder, sig, args):
        i = context.cast(builder, args[1], sig.args[1], types.intp)
        return builder.insert_element(args[0], args[2], i)

    return sig, codegen


@intrinsic
def vjoin(typingctx, low, high, cut):
    """Lanes ``i < cut`` from ``low``, lanes ``i >= cut`` from ``high`` (``cut`` any integer: <= 0
    takes every lane from ``high``, >= the width every lane from ``low``).

    For rows of a symmetric matrix whose lanes below and above the diagonal come from two
    different computations (a lane-wise select; no arithmetic).
    """
    if not (isinstance(low, F64xNType) and low == high and isinstance(cut, types.Integer)):
        return None
    sig = low(low, high, types.intp)

    def codegen(context, builder, sig, args):
        width = sig.args[0].width
        it = ir.IntType(64)
        lanes = ir.Constant(ir.VectorType(it, width), list(range(width)))
        c = context.cast(builder, args[2], sig.args[2], types.intp)
        cv = builder.insert_element(ir.Constant(ir.VectorType(it, width), ir.Undefined), c, ir.Constant(_I32, 0))
        cv = builder.shuffle_vector(
            cv,
            ir.Constant(ir.VectorType(it, width), ir.Undefined),
            ir.Constant(ir.VectorType(_I32, width), [0] * width),
        )
        mask = builder.icmp_signed("<", lanes, cv)
        return builder.select(mask, args[0], args[1])

    return sig, codegen
