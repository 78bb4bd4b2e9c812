"""Fuzz test of the compiled core (``leg_env._core.kernels``) and of every public function that reaches it.

The project's rule: bad input gets a clear Python exception that names the argument and changes nothing,
and compiled code never crashes the interpreter, whatever it is given. Every entry point is called here
with wrong dtypes (int, float32, complex, object, bool, strings, structured, big-endian), wrong shapes,
sizes and ndim, zero-size, non-contiguous (strided, transposed, negative strides), unaligned and
read-only arrays,
NaN, +-inf and huge values, non-physical parameters, lists, scalars and None; the kernels also with wrong
argument counts and keywords, wrong scalar types, outputs one value short, bad modes, task ids and rows,
and garbage (any bit pattern) in every field of the environments' ``state``, ``robots`` and ``settings``
rows (also written after a ``kernels.Batch`` has bound them).

Each case is one call (the random rounds combine a few bad arguments) with one of three expectations:

* ``accept``: it must succeed;
* ``reject``: it must raise ``ValueError`` or ``TypeError`` whose message names the bad argument;
* ``allow``: either (NaN, inf, huge values, another ndim with the same values...).

After a rejected call every array passed (and, for the envs and the draws, the env's arrays and the
generators' states) must be bit-identical to what it was: nothing is half-done. After a successful call
the outputs must have the right shape, the kernels' outputs (pre-filled with a NaN payload that no
arithmetic makes) must be written everywhere, the inputs unchanged, contact modes in 0..3, flags 0 or 1,
and where a public function accepts an input in another form (list, int, float32, non-contiguous,
unaligned, read-only...) the result must be bitwise that of the plain float64 array (to 1e-12 where the
function ends in numpy's linear algebra).

Each group of cases runs in a child process (this file run as a script), so that a segfault or a hang
fails one test and names the case it was in instead of killing pytest. Seeded generation, no hypothesis:
``LEG_ENV_FUZZ_SEED=k`` draws other random rounds (default 0).
Python-side problems already reported (``KNOWN``) are tolerated and listed in a warning.
"""
from __future__ import annotations

import copy
import ctypes
import fnmatch
import gc
import json
import math
import os
import re
import subprocess
import sys
import time
import warnings

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
GROUP_TIMEOUT = 120.0  # s, for one child: a hang fails its group, naming the case

R, A, OK = "reject", "allow", "accept"
NAN, INF = math.nan, math.inf
SENT64 = np.uint64(0x7FF8DEADBEEF0001)  # a quiet NaN payload no arithmetic makes: "not written"
SENT32 = np.uint32(0x7FC0DEAD)
SENT_I64 = np.int64(-0x5EADBEEF5EADBEEF)

# Python-side problems reported to the owners of leg_env/*.py (not the compiled core's): (where, argument,
# case) fnmatch patterns -> what is wrong. A match is tolerated (and listed in a warning); remove an entry
# once its wrapper is fixed, and the case is checked again.
_PUBLIC = "[dchi][yony][nnbt]*.*"  # dynamics.*, contact.*, hybrid.*, integrate.*
_ARRAYS = "[qta]*"  # q, qd, tau, anchor, anchor_x
KNOWN: dict[tuple[str, str, str], str] = {}


# ================================================================================================ child
def _filled(shape, dtype=np.float64) -> np.ndarray:
    a = np.empty(shape, dtype)
    if a.dtype == np.float64:
        a.view(np.uint64)[...] = SENT64
    elif a.dtype == np.float32:
        a.view(np.uint32)[...] = SENT32
    elif a.dtype == np.int64:
        a[...] = SENT_I64
    else:
        a[...] = 0
    return a


def _unwritten(a: np.ndarray) -> int:
    if a.dtype == np.float64:
        return int(np.count_nonzero(a.view(np.uint64) == SENT64)) if a.flags.c_contiguous else int(np.count_nonzero(np.ascontiguousarray(a).view(np.uint64) == SENT64))
    if a.dtype == np.float32:
        return int(np.count_nonzero(np.ascontiguousarray(a).view(np.uint32) == SENT32))
    if a.dtype == np.int64:
        return int(np.count_nonzero(a == SENT_I64))
    return 0


def _bits(x):
    """What 'bit-identical' compares: the bytes of an array (its data, shape and dtype)."""
    if isinstance(x, np.ndarray):
        if x.dtype.names:  # a structured array's bytes, padding included (tobytes of a strided one leaves its padding undefined)
            return (x.shape, x.dtype, np.ascontiguousarray(x).view(np.uint8).tobytes())
        return (x.shape, x.dtype, x.tobytes())  # dtypes compare by value (str() of a structured one is slow)
    return x


def _names_one(message: str, names) -> bool:
    return any(re.search(rf"(?<![A-Za-z0-9_]){re.escape(n)}(?![A-Za-z0-9_])", message) for n in names)


class BadBool:
    def __bool__(self):
        raise RuntimeError("no truth value")


class Run:
    """The cases of one group: each call logged before it is made, problems collected."""

    def __init__(self, log_path: str):
        self.log = open(log_path, "w", buffering=1)
        self.problems: list[dict] = []
        self.cases = 0
        self.slowest: list = []

    def slow(self, where, arg, kind, t0):
        """Keep the slowest cases (the child reports them: a bounded but long loop shows here first)."""
        self.slowest.append((time.perf_counter() - t0, f"{where} | {arg} | {kind}"))
        if len(self.slowest) > 40:
            self.slowest = sorted(self.slowest, reverse=True)[:10]

    def problem(self, where, arg, kind, what, detail=""):
        self.problems.append({"where": where, "arg": arg, "kind": kind, "what": what, "detail": str(detail)[:400]})

    def case(self, where, arg, kind, fn, args=(), kwargs=None, *, expect=OK, names=None, check=None, watch=None,
             inputs=(), outs=()):
        """One call ``fn(*args, **kwargs)``. ``names``: one of them must be in a rejection's message (default
        ``(arg,)``); ``check(result)``: a problem string or None after a success; ``watch()``: a snapshot of
        state outside the arguments that a rejection must leave as it was; ``inputs``: arrays a success must
        leave unchanged; ``outs``: arrays a success must write everywhere."""
        self.log.write(f"{where} | {arg} | {kind}\n")
        self.cases += 1
        kwargs = kwargs or {}
        names = names or (arg,)
        arrays = [a for a in list(args) + list(kwargs.values()) if isinstance(a, np.ndarray)]
        before = [_bits(a) for a in arrays]
        kept_inputs = [_bits(a) for a in inputs]
        watched = watch() if watch else None
        t0 = time.perf_counter()
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                result = fn(*args, **kwargs)
            self.slow(where, arg, kind, t0)
        except (ValueError, TypeError) as e:
            message = f"{type(e).__name__}: {e}"
            if expect == OK:
                self.problem(where, arg, kind, "refused a valid call", message)
                return None
            if not _names_one(str(e), names):
                self.problem(where, arg, kind, f"unclear error: does not name {'/'.join(names)}", message)
            if [_bits(a) for a in arrays] != before or (watch and watch() != watched):
                self.problem(where, arg, kind, "a rejected call changed its arrays or the state", message)
            return None
        except Exception as e:  # noqa: BLE001 - what the rule forbids
            self.problem(where, arg, kind, f"raised {type(e).__name__}, not ValueError/TypeError", e)
            return None
        if expect == R:
            self.problem(where, arg, kind, "accepted bad input")
            return result
        if [_bits(a) for a in inputs] != kept_inputs:
            self.problem(where, arg, kind, "changed an input array")
        for a in outs:
            if isinstance(a, np.ndarray) and _unwritten(a):
                self.problem(where, arg, kind, f"left {_unwritten(a)} output values unwritten")
        if check is not None:
            try:
                bad = check(result)
            except Exception as e:  # noqa: BLE001
                bad = f"the output check raised {type(e).__name__}: {e}"
            if bad:
                self.problem(where, arg, kind, "wrong output", bad)
        return result

    def counts(self, where, fn, args, names):
        """Wrong argument counts and keywords: a TypeError naming the function."""
        self.case(where, "(count)", "one argument too few", fn, args[:-1], expect=R, names=names)
        self.case(where, "(count)", "one argument too many", fn, list(args) + [None], expect=R, names=names)
        self.case(where, "(count)", "no arguments", fn, (), expect=R, names=names)
        self.case(where, "(count)", "a keyword argument", fn, args, {"extra": 1}, expect=R, names=names + ("keyword",))


# ------------------------------------------------------------------------------------------------ values
def _nominal():
    from leg_env.physics.dynamics import static_equilibrium
    from leg_env.physics.params import LegParams

    return static_equilibrium(LegParams())[0]


def _robots(rng, n):
    """Valid (q, qd, tau) of n robots near the nominal posture, the foot just above the ground."""
    q = np.tile(_nominal(), (n, 1)) + 0.05 * rng.standard_normal((n, 5))
    q[:, 1] += 0.003
    return q, 0.3 * rng.standard_normal((n, 5)), 2.0 * rng.standard_normal((n, 2))


DTYPES_F8 = [("int64", np.int64), ("int32", np.int32), ("float32", np.float32), ("float16", np.float16),
             ("complex128", np.complex128), ("bool", np.bool_), ("object", object), ("str", "U8"), ("bytes", "S8"),
             ("structured", [("x", "f8")]), ("big-endian float64", ">f8")]
DTYPES_I8 = [("float64", np.float64), ("int32", np.int32), ("uint64", np.uint64), ("bool", np.bool_), ("object", object),
             ("big-endian int64", ">i8"), ("structured", [("x", "i8")])]
DTYPES_F4 = [("float64", np.float64), ("float16", np.float16), ("int32", np.int32), ("complex64", np.complex64), ("object", object)]
DTYPES_B1 = [("uint8", np.uint8), ("int8", np.int8), ("float64", np.float64), ("object", object)]


def _as_dtype(v, dt):
    dt = np.dtype(dt)
    if dt.names:
        return np.zeros(v.shape, dt)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return v.astype(dt)


def _strided(v):
    s = np.zeros(v.shape[:-1] + (2 * v.shape[-1],), v.dtype) if v.ndim else np.zeros(2, v.dtype)
    if v.ndim:
        s[..., ::2] = v
        return s[..., ::2]
    return s[::2]


def _negative(v):
    return v[::-1].copy()[::-1] if v.ndim else v


def _unaligned(v):
    """The same values one byte off the array's alignment (a C-contiguous array the compiler may not assume
    aligned)."""
    raw = np.zeros(v.nbytes + 1, np.uint8)
    w = raw[1:].view(v.dtype).reshape(v.shape)
    w[...] = v
    return w


def _layouts(v):
    """(kind, same values in another memory layout) of an array."""
    out = []
    if v.ndim and v.shape[-1]:
        out.append(("strided", _strided(v)))
    if v.ndim >= 2:
        out.append(("fortran order (transposed)", np.asfortranarray(v)))
    if v.ndim and v.shape[0]:
        out.append(("negative strides", _negative(v)))
    return out


def array_cases(name, v, role, dtypes, *, defining=False, all_names=(), values=True, value_rule=None):
    """(kind, value, expect, names) of the bad and odd forms of the valid C-side array ``v`` (a kernel's
    argument: C-contiguous, exact dtype, counted values)."""
    nm = (name,)
    anyname = tuple(all_names) or nm
    yield from ((f"dtype {label}", _as_dtype(v, dt), R, nm) for label, dt in dtypes)
    yield "list", v.tolist(), R, nm
    yield "tuple", tuple(v.ravel().tolist()), R, nm
    yield "python float", 0.5, R, nm
    yield "None", None, R, nm
    yield "str", "0.5", R, nm
    yield "bytes of the array", v.tobytes(), R, nm
    yield "memoryview", memoryview(v), OK, nm
    if v.size:
        flat = v.reshape(-1)
        yield "one value short", flat[:-1].copy(), R, (anyname if defining else nm)
        yield "one value long", np.append(flat, flat[:1]), R, (anyname if defining else nm)
    yield "ravelled", v.reshape(-1).copy(), OK, nm
    yield "an extra axis", v.reshape(v.shape + (1,)).copy(), OK, nm
    for kind, w in _layouts(v):
        yield kind, w, (OK if w.flags.c_contiguous else R), nm
    ro = v.copy()
    ro.setflags(write=False)
    yield "read-only", ro, (OK if role == "in" else R), nm
    yield "unaligned", _unaligned(v), A, nm
    if values and role != "out" and v.size and v.dtype == np.float64:
        for val in (NAN, INF, -INF, 1e300, -1e300, 5e-324):
            w = v.copy()
            w.flat[(v.size * 7) // 11] = val
            yield f"a value {val!r}", w, (value_rule(val) if value_rule else A), nm
        yield "all NaN", np.full_like(v, NAN), (value_rule(NAN) if value_rule else A), nm


def scalar_cases(name, rule, values):
    """(kind, value, expect, names) of a real scalar argument: wrong types, then ``values`` by ``rule``."""
    nm = (name,)
    for kind, v in (("str", "0.1"), ("None", None), ("list", [0.1]), ("complex", 1 + 1j), ("array of 2", np.array([0.1, 0.2])),
                    ("object", object())):
        yield kind, v, R, nm
    for v in values:
        yield f"value {v!r}", v, rule(v), nm
    yield "numpy float32", np.float32(values[0]), rule(float(np.float32(values[0]))), nm
    yield "0-d array", np.array(values[0]), rule(values[0]), nm


def int_cases(name, rule, values):
    nm = (name,)
    for kind, v in (("float", 1.0), ("str", "0"), ("None", None), ("huge", 10**30), ("-huge", -(10**30)), ("numpy float", np.float64(0.0)),
                    ("list", [0])):
        yield kind, v, R, nm
    for v in values:
        yield f"value {v!r}", v, rule(v), nm
        yield f"numpy int64 {v!r}", np.int64(v), rule(v), nm


def flag_cases(name):
    nm = (name,)
    yield "array of 2", np.array([1, 0]), R, nm
    yield "__bool__ raises", BadBool(), R, nm
    yield "None", None, OK, nm
    yield "int 2", 2, OK, nm
    yield "numpy bool", np.bool_(True), OK, nm


# ------------------------------------------------------------------------------------------------ kernels
# Every entry point of the compiled module is fuzzed from its row of the module's own table
# (leg_env._core.signatures()): its arguments, their dtypes, shape rules, roles and accepted values. A new entry point is
# fuzzed with no line written here; MAKERS only gives some arguments (by name and kind) a physically meaningful
# valid value, and any other argument gets one from its dtype, shape rule and range.
ARRAY_KINDS = "dPqf?RSBCO"
STRUCT_KINDS = "RSBCO"
STANCE = "leg_env/PlanarLegStance-v0"
N_GENERATORS = 4


def signatures() -> dict:
    from leg_env._core import signatures

    return signatures()


class Arg:
    """One argument of an entry point: its row of ``leg_env._core.signatures()`` (``sig``) and its valid value's maker,
    ``make(n, ctx)`` for a call of n robots."""

    def __init__(self, sig, make):
        self.sig, self.make = sig, make
        self.name, self.kind, self.role, self.rows, self.width = sig["name"], sig["kind"], sig["role"], sig["rows"], sig["width"]

    def accepts(self, v) -> bool:
        """Whether a number (or an integer array's entry) is in the argument's accepted values."""
        if self.sig["range"] is None:
            return True
        lo, hi = self.sig["range"]
        if isinstance(v, float) and math.isnan(v):
            return False
        ok = (v > lo if self.sig["open"] else v >= lo) and v <= hi
        return ok and (not self.sig["whole"] or v == math.floor(v))


class Ctx:
    """What the valid arguments of one call share: the env arrays of n robots of the pinned balance, the robots
    and ranges of a randomised env, the generators and the info builder."""

    def __init__(self, rng, n):
        import gymnasium as gym

        self.rng, self.n = rng, n
        self.env = packed(STANCE, n, bool(n and rng.random() < 0.5), rng)
        if "spec" not in _ENV_ARRAYS:
            env = gym.make("leg_env/PlanarLegBalance-v1", randomize=True).unwrapped
            _ENV_ARRAYS["spec"] = (env.robots.spec.copy(), env.robots.base.copy(), np.asarray(env.robots.limits, dtype=np.float64).copy())
            env.close()
        self.spec, self.base, self.limits = (x.copy() for x in _ENV_ARRAYS["spec"])

    def generators(self):
        from leg_env._core import kernels

        g = kernels.Generators(N_GENERATORS)
        for k in range(N_GENERATORS):
            g.set(k, np.random.Generator(np.random.PCG64(k)) if k % 2 else np.random.PCG64(k))
        return g

    def info(self):
        from leg_env.info import InfoBuilder
        from leg_env.tasks.stance import TASK

        spec, counts, _ = InfoBuilder(TASK, False)._column_spec(self.env["out"].dtype, self.env["state"].dtype, True)
        return spec, counts


def _q(n, ctx):
    return _robots(ctx.rng, n)[0]


def _info_block(kind, width=None):
    def make(n, ctx):
        spec, counts = ctx.info()
        dtype = {"doubles": np.float64, "ints": np.int64, "flags": np.bool_, "vectors": np.float64}[kind]
        shape = (counts[{"doubles": "d", "ints": "i", "flags": "?", "vectors": "v"}[kind]], n) + ((2,) if kind == "vectors" else ())
        return _filled(shape, dtype)

    return make


def _record(n, ctx):
    from leg_env.physics.layout import RECORD

    r = np.empty(n, RECORD)
    r.view(np.uint8)[...] = 0xAB
    return r


MAKERS = {
    # (name, kind): make(n, ctx) -> a valid value (by name where the physics gives it a meaning)
    ("q", "d"): _q,
    ("qd", "d"): lambda n, ctx: _robots(ctx.rng, n)[1],
    ("tau", "d"): lambda n, ctx: _robots(ctx.rng, n)[2],
    ("sigma", "d"): lambda n, ctx: ctx.rng.choice([-1.0, 1.0], n),
    ("mu", "d"): lambda n, ctx: ctx.rng.uniform(0.2, 1.5, n),
    ("knee", "r"): lambda n, ctx: 0.8,
    ("dt", "r"): lambda n, ctx: 0.01,
    ("substeps", "r"): lambda n, ctx: 2,
    ("max_angle", "r"): lambda n, ctx: 0.02,
    ("scale", "r"): lambda n, ctx: 0.1,
    ("stance", "l"): lambda n, ctx: True,
    ("record", "R"): _record,
    ("task", "i"): lambda n, ctx: ctx.env["task"],
    ("lo", "i"): lambda n, ctx: 0,
    ("hi", "i"): lambda n, ctx: n,
    ("noise", "d"): lambda n, ctx: ctx.rng.random((n, 6)),
    ("generators", "g"): lambda n, ctx: ctx.generators(),
    ("rows", "q"): lambda n, ctx: ctx.rng.integers(0, N_GENERATORS, n).astype(np.int64),
    ("spec", "d"): lambda n, ctx: ctx.spec.copy(),
    ("u", "d"): lambda n, ctx: ctx.rng.random(ctx.spec.shape[0]),
    ("base", "B"): lambda n, ctx: ctx.base.copy(),
    ("row", "B"): lambda n, ctx: ctx.base.copy(),
    ("limits", "d"): lambda n, ctx: ctx.limits.copy(),
    ("max_draws", "i"): lambda n, ctx: 100,
    ("spec", "q"): lambda n, ctx: ctx.info()[0].copy(),
    ("doubles", "d"): _info_block("doubles"),
    ("ints", "q"): _info_block("ints"),
    ("flags", "?"): _info_block("flags"),
    ("vectors", "d"): _info_block("vectors"),
}


PLAN_STEPS = 3
PLAN_COLUMNS = {  # a plan's arrays (hop_rollout, ilqr_backward): their columns for a plan of PLAN_STEPS steps
    name: per_step * PLAN_STEPS + extra for name, (per_step, extra) in {
        "corrections": (2, 0), "k": (2, 0), "K": (20, 0), "nominal": (10, 10), "X": (10, 10), "modes": (1, 1), "U": (2, 0),
        "V": (2, 0), "flight_time": (1, 0), "A": (100, 0), "B": (20, 0), "Du": (20, 0), "D": (2, 0), "lx": (10, 0),
        "lxx": (100, 0)}.items()}


def _generic(arg):
    """The valid value of an argument that MAKERS does not name, from its dtype, shape rule and range (a plan's array
    with the columns of a plan of PLAN_STEPS steps)."""
    sig = arg.sig

    def make(n, ctx):
        if arg.kind in STRUCT_KINDS:
            return ctx.env[{"S": "state", "B": "robots", "C": "settings", "O": "out"}[arg.kind]].copy() if arg.kind != "R" else _record(n, ctx)
        if arg.kind == "f":
            return ctx.env["obs"].copy()
        if arg.kind == "P":
            P = _params()
            return np.tile(P, (n, 1)) if (arg.rows == "M" and n > 1 and ctx.rng.random() < 0.5) else P[None, :].copy()
        if arg.kind == "g":
            return ctx.generators()
        rows = {"N": n, "1": 1, "*": 3, "M": 1, "T": 2}.get(arg.rows, 1)
        shape = (rows,) if arg.width == 1 else (rows, arg.width or PLAN_COLUMNS.get(arg.name, 3))
        if arg.rows == "T":
            shape = (rows, n) + ((arg.width,) if arg.width > 1 else ())
        dtype = {"d": np.float64, "q": np.int64, "?": np.bool_}.get(arg.kind)
        if arg.kind in "dq?" and arg.role == "out":
            return _filled(shape, dtype)
        if arg.kind == "q":
            lo, hi = sig["range"] or (0, 3)
            return ctx.rng.integers(int(lo), int(min(hi, lo + 3)) + 1, shape).astype(np.int64)
        if arg.kind == "d":
            if sig["range"] is not None:
                lo, hi = sig["range"]
                return ctx.rng.uniform(lo, min(hi, lo + 1.5), shape)
            return 0.1 * ctx.rng.standard_normal(shape)
        if arg.kind == "?":
            return np.zeros(shape, np.bool_)
        if arg.kind == "r":
            if sig["range"] is None:
                return 0.5
            lo, hi = sig["range"]
            return min(hi, lo + (1.0 if sig["whole"] else 0.01))
        if arg.kind == "i":
            return int(sig["range"][0]) if sig["range"] else 0
        return False  # a flag

    return make


def _params():
    from leg_env.physics.params import LegParams

    return LegParams().array


def kernel_specs() -> dict:
    """{entry point: [Arg]} of every entry point of the compiled module, from its own table."""
    specs = {}
    for name, sig in signatures().items():
        args = []
        for a in sig["args"]:
            arg = Arg(a, None)
            arg.make = MAKERS.get((arg.name, arg.kind)) or _generic(arg)
            if arg.kind == "B" and arg.rows == "*":  # the rows a draw writes into: one per generator
                arg.make = lambda n, ctx: np.repeat(ctx.base, N_GENERATORS)
            args.append(arg)
        specs[name] = args
    return specs


def _value_rule(arg):
    if arg.kind == "P" or arg.sig["range"] is None:
        return None
    return lambda v: OK if arg.accepts(v) else R


def _scalar_values(arg, valid):
    values = [valid, 0.0, -1.0, 1.0, 2.5, NAN, INF, -INF, 1e300, 5e-324, 4096, 4097]
    if arg.sig["range"] is not None:
        lo, hi = arg.sig["range"]
        values += [lo, hi] + ([lo - 1.0] if math.isfinite(lo) else []) + ([hi * 2] if math.isfinite(hi) and hi > 0 else [])
    return values


def _scalar_rule(arg, valid):
    return lambda v: OK if (v == valid or (arg.sig["range"] is not None and arg.accepts(v))) and arg.accepts(v) else (
        A if arg.sig["range"] is None or arg.accepts(v) else R)


def struct_cases(arg, v, n, all_names):
    """(kind, value, expect, names) of a structured array argument (a record, state, robots, settings or out) or a
    float32 observation: its layout cases and its rows by the argument's shape rule."""
    name, nm = arg.name, (arg.name,)
    for kind, w, expect, names in packed_array_cases(name, v, n, all_names):
        if "rows" in kind or "row " in kind:
            continue
        if kind == "one column more" and arg.kind == "d":
            expect = OK
        if kind == "read-only":
            expect = OK if arg.role == "in" else R
        yield kind, w, expect, names
    if arg.kind == "f" or v.ndim != 1 or not v.size:
        return
    for rows in (0, 2, n - 1, n + 1):
        if rows < 0:
            continue
        w = np.repeat(v[:1], rows, axis=0)
        if arg.rows == "N":
            ok = rows == n
        elif arg.rows == "M":
            ok = rows == 1 or (rows == n and n > 0)
        elif arg.rows == "1":
            ok = rows == 1
        else:
            ok = None
        defining = arg.rows == "N" and all_names and all_names[0] == name
        yield f"{rows} rows", w, (A if ok is None else (OK if ok else R)), (all_names if defining else nm)


def arg_cases(arg, v, n, all_names, defining):
    """(kind, value, expect, names) of every bad and odd form of argument ``arg`` whose valid value is ``v``."""
    nm = (arg.name,)
    if arg.kind in "rli":
        if arg.kind == "l":
            yield from flag_cases(arg.name)
        elif arg.kind == "r":
            yield from scalar_cases(arg.name, _scalar_rule(arg, v), _scalar_values(arg, v))
        else:
            values = [v, 0, -1, 1, n, n + 1, 3, 2**40, 2**62, -(2**62)]
            yield from int_cases(arg.name, lambda x: OK if x == v else (A if arg.accepts(x) else R), values)
        return
    if arg.kind == "g":
        from leg_env._core import kernels

        yield "a list of generators", [np.random.PCG64(k) for k in range(N_GENERATORS)], R, nm
        yield "None", None, R, nm
        yield "an int", 4, R, nm
        empty = kernels.Generators(N_GENERATORS)
        yield "no row set", empty, (R if n else OK), nm + ("rows",)
        yield "no rows", kernels.Generators(0), (R if n else OK), nm + ("rows",)
        return
    if arg.kind in STRUCT_KINDS or arg.kind == "f":
        yield from struct_cases(arg, v, n, all_names)
        return
    dtypes = {"d": DTYPES_F8, "P": DTYPES_F8, "q": DTYPES_I8, "?": DTYPES_B1}[arg.kind]
    for kind, w, expect, names in array_cases(arg.name, v, "in" if arg.role == "in" else "out", dtypes, defining=defining, all_names=all_names,
                                              value_rule=_value_rule(arg), values=arg.kind != "P"):
        if kind in ("one value short", "one value long"):
            if arg.rows == "*":
                expect = R if arg.width > 1 else A
            elif arg.rows == "T":
                expect = R if n > 1 else A  # with one robot a block is a row more or less
            elif arg.kind == "P":
                continue  # its rows: _p_cases
        if kind in ("ravelled", "an extra axis") and (arg.width == 0 or arg.kind == "P" and v.ndim == 2 and v.shape[0] > 1):
            expect = R if arg.width == 0 else OK
        if kind in ("ravelled", "an extra axis") and arg.rows == "T":
            expect = A  # a block's rows are its first axis's, or its values over N's
        if kind == "None" and arg.sig["optional"]:
            expect = OK
        yield kind, w, expect, names
    if arg.kind == "P":
        yield from _p_cases(v, n, arg.rows == "1")
    if arg.kind == "q" and arg.role != "out" and v.size and arg.sig["range"] is not None:
        for val in (4, -1, 2**62, -(2**63), 3, 0):
            w = v.copy()
            w.flat[-1] = val
            yield f"a value {val}", w, (A if arg.accepts(val) else R), nm  # what an accepted value means is the entry's


def _p_cases(v, n, one_row):
    """The params array's own cases: rows, and each field non-physical."""
    nm = ("p",)
    for rows in (0, 1, 2, n, n + 1):
        w = np.tile(v[:1], (rows, 1))
        ok = rows == 1 or (rows == n and not one_row and n > 0)
        yield f"{rows} rows", w, (OK if ok else R), nm
    yield "flat (11,)", v[0].copy(), OK, nm
    yield "12 values", np.append(v[0], 0.0), R, nm
    for j in range(11):
        for val in ((0.0, -1.0, NAN, INF, -INF, 1e300) if j < 10 else (0.0, -9.81, NAN, INF, 1e300)):
            w = v.copy()
            w[-1, j] = val
            ok = (0 < val < INF) if j < 10 else (0 <= val < INF)
            yield f"field {j} = {val!r}", w, ((A if val > 1e10 else OK) if ok else R), nm


def _kernel_check(name, spec, args, finite=False):
    """After a valid call: finite outputs of moderate inputs, modes and statuses 0..3, a record's events."""

    def check(_):
        for a, v in zip(spec, args):
            if not isinstance(v, np.ndarray) or a.role == "in":
                continue
            if finite and a.kind == "d" and v.dtype == np.float64 and name not in ("draw_uniform",) and not np.isfinite(v).all():
                return f"{a.name} is not finite at a valid call: {v.ravel()[~np.isfinite(v.ravel())][:3]}"
            if a.name in ("mode", "status") or (name == "contact_mode" and a.name == "out"):
                if v.size and not np.isin(v, [0, 1, 2, 3]).all():
                    return f"{a.name} holds {v[~np.isin(v, [0, 1, 2, 3])][:3]} (a mode or status is 0..3)"
            if a.kind == "R" and v.size and v.dtype.names:
                if not np.isin(v["event_kind"], [-1, 0, 1, 2, 3]).all() or (v["events"] < 0).any():
                    return "record: event_kind outside -1..3 or a negative event count"
        return None

    return check


def _outs(spec, args):
    return [v for a, v in zip(spec, args) if a.role == "out" and isinstance(v, np.ndarray) and v.dtype.kind in "fi"]


def fuzz_kernel(run, name, spec, rng, n, *, variants=True):
    """Every argument of one entry point made bad in turn, on a valid call of n robots."""
    from leg_env._core import kernels

    fn = getattr(kernels, name)
    where = f"kernels.{name}"
    names = tuple(a.name for a in spec)
    array_names = tuple(a.name for a in spec if a.kind in ARRAY_KINDS)
    defining = next((a.name for a in spec if a.rows == "N" and a.kind in ARRAY_KINDS), None)
    all_names = ((defining,) + tuple(x for x in array_names if x != defining)) if defining else array_names

    def valid():
        ctx = Ctx(rng, n)
        return [a.make(n, ctx) for a in spec]

    def call(arg, kind, args, expect, names_, finite=False):
        ins = [v for a, v in zip(spec, args) if a.role == "in" and isinstance(v, np.ndarray)]
        run.case(where, arg, kind, fn, args, expect=expect, names=names_, check=_kernel_check(name, spec, args, finite), inputs=ins,
                 outs=_outs(spec, args) if expect == OK else ())

    base = valid()
    call("(all)", f"valid, {n} robots", base, OK, names, finite=True)
    for k, a in enumerate(spec):
        for kind, w, expect, names_ in arg_cases(a, base[k], n, all_names, defining=a.name == defining):
            args = valid()
            args[k] = w
            call(a.name, kind, args, expect, names_)
    if variants:
        run.counts(where, fn, base, (name,))
        # one array as two arguments, one of them written: a kernel reads its inputs while it writes its outputs
        arrays = [k for k, a in enumerate(spec) if a.kind in ARRAY_KINDS]
        for i in arrays:
            for o in arrays:
                if i >= o or (spec[i].role == "in" and spec[o].role == "in"):
                    continue
                args = valid()
                x, y = args[i], args[o]
                if not (isinstance(x, np.ndarray) and isinstance(y, np.ndarray) and x.size and y.size and x.dtype == y.dtype):
                    continue
                shared = np.empty(max(x.size, y.size), x.dtype)  # both at the start of one buffer
                shared[: x.size] = x.reshape(-1)
                args[i], args[o] = shared[: x.size].reshape(x.shape), shared[: y.size].reshape(y.shape)
                run.case(where, spec[o].name, f"sharing memory with {spec[i].name}", fn, args, expect=R, names=(spec[i].name, spec[o].name))
    return base


def fuzz_kernel_random(run, name, spec, rng, rounds):
    """Random rounds: a random number of robots and up to three arguments made bad at once."""
    from leg_env._core import kernels

    fn = getattr(kernels, name)
    array_names = tuple(a.name for a in spec if a.kind in ARRAY_KINDS)
    defining = next((a.name for a in spec if a.rows == "N" and a.kind in ARRAY_KINDS), None)
    all_names = ((defining,) + tuple(x for x in array_names if x != defining)) if defining else array_names
    for r in range(rounds):
        n = 1 if defining is None else int(rng.choice([0, 1, 2, 3, 7]))
        ctx = Ctx(rng, n)
        args = [a.make(n, ctx) for a in spec]
        picks = rng.choice(len(spec), size=int(rng.integers(1, 4)), replace=False)
        expects, names, kinds = [], [], []
        for k in picks:
            a = spec[k]
            pool = list(arg_cases(a, args[k], n, all_names, defining=a.name == defining))
            kind, w, expect, nm = pool[int(rng.integers(len(pool)))]
            args[k] = w
            expects.append(expect)
            names.extend(nm)
            kinds.append(f"{a.name}: {kind}")
        expect = R if R in expects else A  # several changes at once: a rejection must name one of them
        run.case(f"kernels.{name}", "(random)", f"round {r}, {n} robots: " + "; ".join(kinds), fn, args, expect=expect,
                 names=tuple(names) + all_names)


# ------------------------------------------------------------------------------------------------ packed
# The environments' arrays (leg_env.physics.layout): 1-d structured arrays of the C structs, state and out a row per
# robot, robots one row or a row per robot, settings one row; obs a float32 matrix.
ARRAYS = ("state", "robots", "settings", "out", "obs")
_ENV_ARRAYS: dict = {}


def env_arrays(env_id):
    """{task, state, robots, settings, out, obs} of a freshly reset env of ``env_id`` (one row each)."""
    if env_id not in _ENV_ARRAYS:
        import gymnasium as gym

        env = gym.make(env_id).unwrapped
        env.reset(seed=1)
        _ENV_ARRAYS[env_id] = {"task": env.task.kernel, "state": env._state.copy(), "robots": env._robots.copy(),
                               "settings": env._settings.copy(), "out": env._out.copy(), "obs": env._obs.copy()}
        env.close()
    return _ENV_ARRAYS[env_id]


def packed(env_id, n, per_robot=False, rng=None):
    """Fresh arrays of n robots of ``env_id`` (a dict of ARRAYS and task)."""
    e = env_arrays(env_id)
    a = {"task": e["task"], "state": np.repeat(e["state"], n), "robots": np.repeat(e["robots"], n if per_robot else 1),
         "settings": e["settings"].copy(), "out": np.repeat(e["out"], n), "obs": np.repeat(e["obs"], n, axis=0)}
    if rng is not None and n:
        a["state"]["q"][:, 2:5] += 0.02 * rng.standard_normal((n, 3))  # different robots (trig is recomputed by a start)
    return a


def _leaves(dtype, prefix="", offset=0):
    """(name, byte offset, scalar dtype, count) of every field of a structured dtype, nested ones flattened."""
    for name in dtype.names:
        sub, off = dtype.fields[name][:2]
        if sub.names:
            yield from _leaves(sub, f"{prefix}{name}.", offset + off)
        else:
            yield f"{prefix}{name}", offset + off, sub.base, int(np.prod(sub.shape)) if sub.shape else 1


def _poke(a, row, offset, base, k, value):
    """Write ``value`` as raw bytes of ``base`` into element k of a field of row ``row`` (any bit pattern: a
    bool field gets the byte as given)."""
    raw = np.array([value], dtype=np.uint8 if base == np.bool_ else base).view(np.uint8)
    at = offset + k * base.itemsize
    a.view(np.uint8).reshape(a.shape[0], a.dtype.itemsize)[row, at:at + raw.size] = raw


def _values_of(base):
    if base.kind == "f":
        return (NAN, INF, -INF, 1e300, -1e300, 0.0, -1.0, 5000.0)
    if base.kind in "iu":
        return (-1, 0, 4, 4097, 2**31 - 1, -(2**31))
    return (0, 1, 2, 255)  # bool: raw bytes


def _obs_dim(task, unilateral, action=False):
    """The observation's width the C core requires: the balance's 12 on the pinned foot, 18 on the unilateral ground;
    the push's 19 and the hop's 22, on the unilateral ground only (None: refused); 2 more with observe_action."""
    if task == 0:
        width = 18 if unilateral else 12
    elif not unilateral:
        return None
    else:
        width = 19 if task == 1 else 22
    return width + (2 if action else 0)


def field_rule(array, field, value, task, obs_cols, modes, takes_obs):
    """(expect, names) of writing ``value`` into ``field`` of ``array``: the checked fields are refused out of their
    range (physical parameters, step settings, contact modes, the ground that sets obs's width), the rest any value."""
    # robots: checked where a row is written (LegParams, leg_env.randomize), not at every call: any value is allowed
    if array == "settings":
        ok = {"dt": lambda v: 0 < v < INF, "max_angle": lambda v: v > 0, "max_rate": lambda v: v > 0,
              "substeps": lambda v: 1 <= v <= 4096, "motor_speed": lambda v: v > 0}.get(field)
        if ok is not None:
            return (A if ok(value) else R), ("settings",)
        if field == "unilateral" and takes_obs:  # the ground, which sets obs's width (with the valid row's last action, if observed)
            action = obs_cols in (_obs_dim(task, True, True), _obs_dim(task, False, True))
            return (A if _obs_dim(task, bool(value), action) == obs_cols else R), ("obs", "settings")
        if field == "observe_action" and takes_obs:  # two more columns
            return (A if _obs_dim(task, task != 0 or obs_cols >= 18, bool(value)) == obs_cols else R), ("obs", "settings")
    if array == "state" and field in ("mode", "prev_mode") and modes:
        return (A if value in (0, 1, 2, 3) else R), ("state",)
    return A, (array,)


def packed_array_cases(name, v, n, all_names):
    """(kind, value, expect, names) of one array of an env call: a structured row array or obs."""
    nm = (name,)
    matrix = v.dtype.names is None  # obs (float32), or a float64 matrix (draw_uniform's out)
    if matrix:
        yield from ((f"dtype {label}", _as_dtype(v, dt), R, nm) for label, dt in (DTYPES_F4 if v.dtype == np.float32 else DTYPES_F8))
        yield "1-d (ravelled)", v.reshape(-1).copy(), R, nm
        yield "3-d", v.reshape(v.shape + (1,)).copy(), R, nm
        yield "one column short", v[:, :-1].copy(), R, nm
        yield "one column more", np.zeros((v.shape[0], v.shape[1] + 1), v.dtype), (OK if name == "out" else R), nm
    else:
        size = v.dtype.itemsize
        yield "float64 of the same bytes", v.view(np.float64).copy(), R, nm
        yield "raw bytes (void) of its size", v.view((np.void, size)).copy(), OK, nm
        yield "void one byte short", np.zeros(v.shape, (np.void, size - 1)), R, nm
        yield "void one byte long", np.zeros(v.shape, (np.void, size + 1)), R, nm
        yield "2-d (n, 1)", v.reshape(-1, 1).copy(), R, nm
        yield "bytes of the array", v.tobytes(), R, nm
        if v.size:
            yield "a numpy scalar record", v[0], R, nm
    yield "list", v.tolist(), R, nm
    yield "None", None, R, nm
    yield "python float", 1.0, R, nm
    yield "str", "state", R, nm
    if name == "robots":
        for rows in (0, 2, n, n + 1):
            yield f"{rows} rows", np.repeat(v[:1], rows, axis=0), (OK if rows in (1, n) else R), nm
    elif name == "settings":
        for rows in (0, 2):
            yield f"{rows} rows", np.repeat(v[:1], rows, axis=0), R, nm
    else:
        yield "one row short", v[:-1].copy(), R, (all_names if name == "state" else nm)
        yield "one row more", np.concatenate([v, v[:1]]), R, (all_names if name == "state" else nm)
    for kind, w in _layouts(v) if matrix else (("strided", np.repeat(v, 2)[::2]), ("negative strides", _negative(v))):
        yield kind, w, (OK if w.flags.c_contiguous else R), nm
    ro = v.copy()
    ro.setflags(write=False)
    yield "read-only", ro, (OK if name in ("robots", "settings") else R), nm
    yield "unaligned", _unaligned(v), A, nm


def _packed_check(a, started=False, lo=None, hi=None, before=None):
    """After a successful call on the arrays ``a``: modes 0..3, flags 0 or 1, a start's observation written,
    physics_range's rows outside lo .. hi untouched."""
    state, out, obs = a["state"], a["out"], a["obs"]

    def check(_):
        if isinstance(state, np.ndarray) and state.dtype.names and not np.isin(state["mode"], [0, 1, 2, 3]).all():
            return f"state modes {state['mode']}"
        if isinstance(out, np.ndarray) and out.dtype.names:
            for flag in ("terminated", "unilateral_violation", "friction_violation", "numerical_failure"):
                if not np.isin(out[flag].view(np.uint8), [0, 1]).all():
                    return f"out[{flag!r}] is not 0 or 1"
        if started and isinstance(obs, np.ndarray) and obs.dtype == np.float32 and _unwritten(obs):
            return f"{_unwritten(obs)} observation values unwritten"
        if before is not None:
            rows = np.r_[0:lo, hi:state.shape[0]]
            for x, y in zip((state, out), before):
                if x[rows].tobytes() != y[rows].tobytes():
                    return f"physics_range({lo}, {hi}) changed rows outside lo .. hi"
        return None

    return check


def env_entries() -> dict:
    """The entry points that step or start an env's arrays (an ``env_state`` they write): {name: argument names}."""
    return {name: tuple(a["name"] for a in sig["args"]) for name, sig in signatures().items() if any(a["kind"] == "S" and a["role"] == "inout" for a in sig["args"])}


def env_call(name, a, n, noise=None, scale=0.0):
    """The arguments of env entry point ``name`` on the arrays dict ``a`` of n robots (all rows; noise as given)."""
    values = {"task": a["task"], "lo": 0, "hi": n, "noise": noise, "scale": scale, **{k: a[k] for k in ARRAYS}}
    return [values[x] for x in env_entries()[name]]


def packed_calls(kernels, task):
    """name -> (fn, args of the arrays dict, starts?, reads obs?, checks modes?): every env entry point (read from the
    module's table), a start with noise, the single env's Batch and the task's own calls."""
    from leg_env import tasks as task_modules

    t = task_modules.get(["stance", "push", "hop"][task])
    calls = {f"kernels.{name}": (getattr(kernels, name), lambda a, n, name=name: env_call(name, a, n), name == "start", "obs" in names,
                                 name != "start") for name, names in env_entries().items()}
    calls["kernels.start (noise)"] = (kernels.start, lambda a, n: env_call("start", a, n, np.full((n, 6), 0.3), 0.1), True, True, False)
    calls["kernels.Batch"] = (lambda *x: kernels.Batch(*x).step_one(0.2, -0.3), lambda a, n: [task, a["state"], a["robots"], a["settings"], a["out"],
                                                                                             a["obs"]], False, True, True)
    calls[f"tasks.{t.name}.TASK.assess"] = (t.assess, lambda a, n: [a["state"], a["robots"], a["settings"], a["out"], a["obs"]], False, True, True)
    calls[f"tasks.{t.name}.TASK.start"] = (t.start, lambda a, n: [a["state"], a["robots"], a["settings"], a["out"], a["obs"]], True, True, False)
    return calls


def fuzz_packed(run, env_id, rng):
    from leg_env._core import kernels

    n = 3
    task = env_arrays(env_id)["task"]
    short = env_id.split("/")[-1]
    for where, (fn, build, starts, takes_obs, modes) in packed_calls(kernels, task).items():
        where = f"{where} [{short}]"
        batch = where.startswith("kernels.Batch")
        for per_robot in (False, True):
            a = packed(env_id, n, per_robot, rng)
            if starts:
                a["obs"] = _filled(a["obs"].shape, np.float32)
            run.case(where, "(all)", f"valid, robots {'per robot' if per_robot else 'shared'}", fn, build(a, n), expect=OK,
                     check=_packed_check(a, starts), inputs=[a["robots"], a["settings"]])
        names = ARRAYS if takes_obs else ARRAYS[:4]
        base = packed(env_id, n, False, rng)
        for name in names:
            for kind, w, expect, nm in packed_array_cases(name, base[name], n, names):
                a = packed(env_id, n, False, rng)
                a[name] = w
                run.case(where, name, kind, fn, build(a, n), expect=expect, names=nm, check=_packed_check(a))
        # garbage in every field of state, robots and settings: the checked ones refused out of range, the rest
        # any value (no crash, no hang, nothing written out of bounds)
        full = "kernels.step" in where or "kernels.assess" in where or batch
        for array in ("state", "robots", "settings"):
            leaves = list(_leaves(base[array].dtype))
            if not full:
                leaves = [leaves[i] for i in rng.choice(len(leaves), min(6, len(leaves)), replace=False)]
            for field, offset, dt, count in leaves:
                for k in sorted({0, count - 1}):
                    for value in _values_of(dt):
                        a = packed(env_id, n, array == "robots" and bool(rng.random() < 0.5), rng)
                        _poke(a[array], int(rng.integers(a[array].shape[0])), offset, dt, k, value)
                        expect, nm = field_rule(array, field, value, task, a["obs"].shape[1], modes, takes_obs)
                        run.case(where, array, f"{field}[{k}] = {value!r}", fn, build(a, n), expect=expect, names=nm,
                                 check=_packed_check(a))
        # no robots
        a = packed(env_id, 0, False, rng)
        run.case(where, "(all)", "zero robots", fn, build(a, 0), expect=R if batch else OK, names=("state",))
        a["robots"] = a["robots"][:0]
        run.case(where, "robots", "zero robots, zero robots rows", fn, build(a, 0), expect=R, names=("robots",))
        if where.startswith("kernels.") and not batch:
            kname = where.split(" ")[0].split(".")[1]
            run.counts(where, fn, build(packed(env_id, n, False, rng), n), (kname,))


def fuzz_packed_scalars(run, env_id, rng):
    """lo / hi, task ids, noise and scale."""
    from leg_env._core import kernels

    n = 3
    task = env_arrays(env_id)["task"]
    short = env_id.split("/")[-1]

    def pr(lo, hi):
        a = packed(env_id, n, False, rng)
        return [task, lo, hi, a["state"], a["robots"], a["settings"], a["out"], a["obs"]], a, (a["state"].copy(), a["out"].copy())

    good = lambda v: 0 <= v <= n  # noqa: E731
    for kind, v, expect, nm in int_cases("lo", lambda v: OK if good(v) else R, [0, 1, n, -1, n + 1, 2**62]):
        args, a, before = pr(v, n)
        lo = int(v) if isinstance(v, (int, np.integer)) and not isinstance(v, bool) and 0 <= int(v) <= n else 0
        run.case(f"kernels.step [{short}]", "lo", kind, kernels.step, args, expect=expect, names=("lo", "hi"),
                 check=_packed_check(a, lo=lo, hi=n, before=before))
    for kind, v, expect, nm in int_cases("hi", lambda v: OK if good(v) else R, [0, 2, n, -1, n + 1, -(2**62)]):
        args, a, before = pr(0, v)
        hi = int(v) if isinstance(v, (int, np.integer)) and not isinstance(v, bool) and 0 <= int(v) <= n else n
        run.case(f"kernels.step [{short}]", "hi", kind, kernels.step, args, expect=expect, names=("lo", "hi"),
                 check=_packed_check(a, lo=0, hi=hi, before=before))
    args, a, before = pr(2, 1)
    run.case(f"kernels.step [{short}]", "lo", "lo > hi", kernels.step, args, expect=R, names=("lo", "hi"))
    args, a, before = pr(True, n)
    run.case(f"kernels.step [{short}]", "lo", "True", kernels.step, args, expect=OK,
             check=_packed_check(a, lo=1, hi=n, before=before))
    for fname in ("assess", "start", "Batch"):
        fn = getattr(kernels, fname)
        for kind, v, expect, nm in int_cases("task", lambda v: OK if v == task else (A if 0 <= v <= 2 else R), [task, -1, 3, 2**40, 0, 1, 2]):
            a = packed(env_id, n, False, rng)
            args = [v, a["state"], a["robots"], a["settings"], a["out"], a["obs"]] + ([None, 0.0] if fname == "start" else [])
            run.case(f"kernels.{fname} [{short}]", "task", kind, fn, args, expect=expect, names=("task", "obs"), check=_packed_check(a))
    # start's noise and scale
    fn = kernels.start
    for kind, v, expect, nm in scalar_cases("scale", lambda v: OK if 0 <= v < INF else R, [0.1, 0.0, -0.1, NAN, INF, 1e300, 5e-324]):
        a = packed(env_id, n, False, rng)
        run.case(f"kernels.start [{short}]", "scale", kind, fn, [task, a["state"], a["robots"], a["settings"], a["out"], a["obs"],
                                                                 rng.random((n, 6)), v], expect=expect, names=nm, check=_packed_check(a))
    for kind, w, expect, nm in array_cases("noise", rng.random((n, 6)), "in", DTYPES_F8):
        if kind == "None":
            expect = OK  # the states as they are
        a = packed(env_id, n, False, rng)
        run.case(f"kernels.start [{short}]", "noise", kind, fn, [task, a["state"], a["robots"], a["settings"], a["out"], a["obs"], w, 0.1],
                 expect=expect, names=nm, check=_packed_check(a))


def fuzz_packed_random(run, env_id, rng, rounds):
    """Random rounds: garbage in several fields of state, robots and settings at once, stepped and evaluated."""
    from leg_env._core import kernels

    task = env_arrays(env_id)["task"]
    short = env_id.split("/")[-1]
    leaves = {name: list(_leaves(env_arrays(env_id)[name].dtype)) for name in ("state", "robots", "settings")}
    for r in range(rounds):
        n = int(rng.integers(1, 6))
        a = packed(env_id, n, bool(rng.random() < 0.5), rng)
        cells, kinds = {}, []  # (array, row, field, k) -> the value written last
        for _ in range(int(rng.integers(1, 5))):
            array = str(rng.choice(["state", "robots", "settings"]))
            field, offset, dt, count = leaves[array][int(rng.integers(len(leaves[array])))]
            row, k = int(rng.integers(a[array].shape[0])), int(rng.integers(count))
            values = _values_of(dt)
            value = values[int(rng.integers(len(values)))]
            _poke(a[array], row, offset, dt, k, value)
            cells[(array, row, field, k)] = value
            kinds.append(f"{array}[{row}].{field}[{k}] = {value!r}")
        label = f"round {r}, {n} robots: " + "; ".join(kinds)
        names = ("state", "robots", "settings", "obs")
        for fname, args, takes_obs, modes in (
            ("step", [task, 0, n, a["state"], a["robots"], a["settings"], a["out"], a["obs"]], True, True),
            ("assess", [task, a["state"], a["robots"], a["settings"], a["out"], a["obs"]], True, True),
            ("start", [task, a["state"], a["robots"], a["settings"], a["out"], a["obs"], None, 0.0], True, False),
        ):
            expects = [field_rule(array, field, value, task, a["obs"].shape[1], modes, takes_obs)[0]
                       for (array, row, field, k), value in cells.items()]
            before = (a["state"].copy(), a["out"].copy()) if fname == "step" else None
            run.case(f"kernels.{fname} [{short}]", "(random)", label, getattr(kernels, fname), args, expect=R if R in expects else A,
                     names=names, check=_packed_check(a, lo=0, hi=n, before=before))


def fuzz_batch(run, env_id, rng):
    """kernels.Batch: its step_one and start arguments, and its arrays written after it bound them."""
    from leg_env._core import kernels

    short = env_id.split("/")[-1]
    where = f"kernels.Batch [{short}]"
    task = env_arrays(env_id)["task"]

    def bound():
        a = packed(env_id, 1, False, rng)
        return kernels.Batch(task, a["state"], a["robots"], a["settings"], a["out"], a["obs"]), a

    def watch_of(a, names=("state", "out", "obs")):
        return lambda: [_bits(a[x]) for x in names]

    for arg, pos in (("a0", 0), ("a1", 1)):
        for kind, v, expect, nm in scalar_cases(arg, lambda v: OK if math.isfinite(v) else R, [0.3, NAN, INF, -INF, 1e300, -1e300]):
            batch, a = bound()
            args = [0.1, -0.1]
            args[pos] = v
            run.case(f"{where}.step_one", arg, kind, batch.step_one, args, expect=expect, names=(arg, "action"), watch=watch_of(a),
                     check=lambda r: None if isinstance(r, float) and not math.isinf(r) else f"reward {r!r}")
    batch, a = bound()
    run.counts(f"{where}.step_one", batch.step_one, [0.1, 0.2], ("step_one",))
    # the arrays written after binding: the next call refuses what a call would refuse, and changes nothing
    for array in ("state", "robots", "settings"):
        for field, offset, dt, count in _leaves(a[array].dtype):
            for value in _values_of(dt):
                for method, modes in (("step_one", True), ("start", False)):
                    batch, a = bound()
                    _poke(a[array], 0, offset, dt, 0, value)
                    expect, nm = field_rule(array, field, value, task, a["obs"].shape[1], modes, True)
                    args = [0.2, 0.2] if method == "step_one" else [None, 0.0]
                    run.case(f"{where}.{method}", array, f"{field}[0] = {value!r} after binding", getattr(batch, method), args,
                             expect=expect, names=nm, watch=watch_of(a))
    for kind, args, expect, nm in (
        ("None, 0", [None, 0.0], OK, ("noise",)), ("None, NaN", [None, NAN], R, ("scale",)),
        ("noise, 0.1", [rng.random(6), 0.1], OK, ("noise",)), ("noise, 0", [rng.random(6), 0.0], OK, ("noise",)),
        ("noise short", [rng.random(5), 0.1], R, ("noise",)), ("noise long", [rng.random(7), 0.1], R, ("noise",)),
        ("noise float32", [rng.random(6).astype(np.float32), 0.1], R, ("noise",)), ("noise str", ["x", 0.1], R, ("noise",)),
        ("noise strided", [_strided(rng.random(6)), 0.1], R, ("noise",)), ("noise NaN", [np.full(6, NAN), 0.1], A, ("noise",)),
        ("scale NaN", [rng.random(6), NAN], R, ("scale",)), ("scale -1", [rng.random(6), -1.0], R, ("scale",)),
        ("scale inf", [rng.random(6), INF], R, ("scale",)), ("scale str", [rng.random(6), "x"], R, ("scale",)),
        ("scale None", [rng.random(6), None], R, ("scale",)), ("one argument", [None], R, ("start",)),
        ("three arguments", [None, 0.0, 1], R, ("start",)),
    ):
        batch, a = bound()
        run.case(f"{where}.start", "noise/scale", kind, batch.start, args, expect=expect, names=nm, watch=watch_of(a))
    a = packed(env_id, 1, False, rng)
    run.counts(where, kernels.Batch, [task, a["state"], a["robots"], a["settings"], a["out"], a["obs"]], ("Batch",))
    # it holds its arrays: the caller's names can go
    a = packed(env_id, 1, False, rng)
    batch = kernels.Batch(task, a.pop("state"), a.pop("robots"), a.pop("settings"), a.pop("out"), a.pop("obs"))
    gc.collect()
    for k in range(20):
        run.case(f"{where}.step_one", "(lifetime)", f"step {k} after the arrays' names are gone", batch.step_one, [0.5, -0.5], expect=OK)
    batch, a = bound()
    for k in range(60):  # a random walk: a reward every step, never a crash
        a0, a1 = rng.uniform(-3, 3, 2)
        run.case(f"{where}.step_one", "(walk)", f"step {k}", batch.step_one, [a0, a1], expect=OK)


# ------------------------------------------------------------------------------------------------ draws
def _capsule(name: bytes):
    """A capsule that is not numpy's BitGenerator one (another name)."""
    new = ctypes.pythonapi.PyCapsule_New
    new.restype = ctypes.py_object
    new.argtypes = [ctypes.c_void_p, ctypes.c_char_p, ctypes.c_void_p]
    _capsule.keep = getattr(_capsule, "keep", []) + [ctypes.create_string_buffer(64), name]
    return new(ctypes.addressof(_capsule.keep[-2]), _capsule.keep[-1], None)


def fuzz_draws(run, rng):
    """The draws' meaning (every argument's forms are the generic fuzz's): the numbers Generator.random gives, rows
    and generators that must exist, Generators itself, and the robots a draw refuses or writes."""
    from leg_env._core import kernels
    import gymnasium as gym

    bgs = [np.random.PCG64(k) for k in range(4)]

    def states():
        return [json.dumps(bg.state, default=str) for bg in bgs]

    def drawn(rows, cols):
        copies = [copy.deepcopy(bg) for bg in bgs]
        return np.array([np.random.Generator(copies[r]).random(cols) for r in rows]).reshape(len(rows), cols)

    def check_draw(rows, out):
        expected = drawn(rows, out.shape[1])
        return lambda _: None if np.array_equal(out, expected) else "the draws differ from Generator.random's"

    def held(kind="mixed", unset=()):
        g = kernels.Generators(len(bgs))
        for k, bg in enumerate(bgs):
            if k not in unset:
                g.set(k, bg if kind == "BitGenerator" or (kind == "mixed" and k % 2) else np.random.Generator(bg))
        return g

    where = "kernels.draw_uniform"
    rows = rng.integers(0, 4, 5).astype(np.int64)
    for kind in ("mixed", "Generator", "BitGenerator"):
        out = _filled((5, 3))
        run.case(where, "(all)", f"valid, a Generators of {kind}", kernels.draw_uniform, [held(kind), rows, out], expect=OK,
                 check=check_draw(rows, out), outs=[out])
    for val in (-1, 4, 2**62, -(2**63)):
        r_ = rows.copy()
        r_[2] = val
        run.case(where, "rows", f"a value {val}", kernels.draw_uniform, [held(), r_, _filled((5, 3))], expect=R, names=("rows", "generators"),
                 watch=states)
    r_ = rows.copy()
    r_[1] = 3
    run.case(where, "generators", "a row not set", kernels.draw_uniform, [held(unset=(3,)), r_, _filled((5, 3))], expect=R,
             names=("rows", "generators"), watch=states)
    for kind, g in (("a list", list(bgs)), ("a tuple", tuple(bgs)), ("None", None), ("a BitGenerator", bgs[0])):
        run.case(where, "generators", kind, kernels.draw_uniform, [g, rows, _filled((5, 3))], expect=R, names=("generators",), watch=states)
    run.case(where, "(all)", "no rows, an empty Generators", kernels.draw_uniform, [kernels.Generators(0), np.zeros(0, np.int64), np.zeros((0, 3))],
             expect=OK)
    run.case(where, "(all)", "no columns", kernels.draw_uniform, [held(), rows, np.zeros((5, 0))], expect=OK)

    where = "kernels.Generators"
    for kind, args, expect in (("n = -1", (-1,), R), ("n huge", (2**40,), R), ("n one past the bound", (kernels.MAX_ROWS + 1,), R),
                               ("n a float", (2.0,), R), ("n a str", ("4",), R), ("no n", (), R)):
        run.case(where, "n", kind, kernels.Generators, list(args), expect=expect, names=("n", "Generators", "integer"))
    g = held()
    for kind, args, expect in (("row -1", (-1, bgs[0]), R), ("row n", (4, bgs[0]), R), ("a bare capsule", (0, bgs[0].capsule), R),
                               ("None", (0, None), R), ("an int", (0, 7), R), ("numpy RandomState", (0, np.random.RandomState(0)), A),
                               ("row a float", (0.0, bgs[0]), R)):
        run.case(where, "set", kind, g.set, list(args), expect=expect, names=("row", "generator", "set", "index", "integer"), watch=states)
    expected = drawn(range(4), 2)  # the refused sets left every row drawing from its own generator
    after = np.empty((4, 2))
    kernels.draw_uniform(g, np.arange(4, dtype=np.int64), after)
    if not np.array_equal(after, expected):
        run.problem(where, "set", "a refused set", "changed a row's generator")

    # draw_robots(generators, rows, spec, base, limits, max_draws, robots, rejected) and robot_params(u, spec, base, limits, row):
    env = gym.make("leg_env/PlanarLegBalance-v1", randomize=True).unwrapped
    spec, base, limits = env.robots.spec.copy(), env.robots.base.copy(), np.asarray(env.robots.limits, dtype=np.float64).copy()
    env.close()
    first_derived = base.dtype.fields["q_nom"][1] // 8  # the drawn fields are the doubles before q_nom
    where = "kernels.draw_robots"

    def robots_args(rows_=None):
        return [held(), np.arange(3, dtype=np.int64) if rows_ is None else rows_, spec.copy(), base.copy(), limits.copy(), 100,
                np.repeat(base, 4), _filled(3, np.int64)]

    def check_robots(args):
        rejected, robots, rows = args[7], args[6], args[1]

        def check(_):
            if ((rejected < 0) | (rejected > 100)).any():
                return f"rejected counts {rejected}"
            untouched = np.setdiff1d(np.arange(robots.shape[0]), rows)
            if robots[untouched].tobytes() != np.repeat(base, len(untouched)).tobytes():
                return "rows of robots not drawn were changed"
            return None

        return check

    def robots_watch(args):
        return lambda: states() + [_bits(a) for a in args if isinstance(a, np.ndarray)]

    args = robots_args()
    run.case(where, "(all)", "valid", kernels.draw_robots, args, expect=OK, check=check_robots(args), outs=[args[7]])
    for col, val, expect in ((0, first_derived, R), (0, first_derived - 1, OK), (0, -1.0, R), (0, 1.5, R), (0, NAN, R), (1, 3.0, R),
                             (1, -1.0, R), (1, NAN, R), (0, 1e300, R), (2, NAN, A), (3, 1e300, A), (2, -INF, A)):
        args = robots_args()
        args[2][0, col] = val
        run.case(where, "spec", f"spec[0, {col}] = {val!r}", kernels.draw_robots, args, expect=expect, names=("spec",),
                 watch=robots_watch(args), check=check_robots(args) if expect == OK else None)
    args = robots_args()
    args[2] = np.repeat(spec[:1], 65, axis=0)
    run.case(where, "spec", "65 rows (one past the most)", kernels.draw_robots, args, expect=R, names=("spec",), watch=robots_watch(args))
    for field, offset, dt, count in _leaves(base.dtype):
        for value in _values_of(dt):
            args = robots_args()
            _poke(args[3], 0, offset, dt, 0, value)
            run.case(where, "base", f"{field}[0] = {value!r}", kernels.draw_robots, args, expect=A, names=("base",))
    args = robots_args(rows_=np.array([0, 5, 1], np.int64))
    run.case(where, "rows", "a row past generators and robots", kernels.draw_robots, args, expect=R, names=("rows",), watch=robots_watch(args))
    args = robots_args(rows_=np.array([0, 3, 1], np.int64))
    args[6] = np.repeat(base, 3)
    run.case(where, "rows", "a row past robots", kernels.draw_robots, args, expect=R, names=("rows",), watch=robots_watch(args))

    where = "kernels.robot_params"
    F = spec.shape[0]

    def rp_args():
        row = base.copy()
        row.view(np.uint64)[...] = SENT64
        return [rng.random(F), spec.copy(), base.copy(), limits.copy(), row]

    def written(row):
        return lambda r: (None if isinstance(r, bool) else f"returned {r!r}") or (
            "row left unwritten" if (row.view(np.uint64) == SENT64).any() else None)

    args = rp_args()
    run.case(where, "(all)", "valid", kernels.robot_params, args, expect=OK, inputs=args[:4], check=written(args[4]))
    for kind, u in (("u one short", rng.random(F - 1)), ("u one long", rng.random(F + 1))):
        args = rp_args()
        args[0] = u
        run.case(where, "u", kind, kernels.robot_params, args, expect=R, names=("u", "spec"))

    for fname in ("layouts", "observation", "table"):
        fn = getattr(kernels, fname)
        run.case(f"kernels.{fname}", "(all)", "no arguments", fn, [], expect=OK)
        run.case(f"kernels.{fname}", "(count)", "one argument", fn, [1], expect=R, names=(fname,))


# ------------------------------------------------------------------------------------------------ public
def _shapes(result):
    if isinstance(result, tuple):
        return tuple(np.shape(x) for x in result)
    return (np.shape(result),)


def _arrays_of(result):
    return list(result) if isinstance(result, tuple) else [result]


# public functions that finish in numpy's linear algebra (matmul, solve, einsum), whose summation order may
# depend on the memory layout of their inputs: compared to 1e-12, the others bit for bit
NUMPY_TAIL = ("integrate.project_velocity", "dynamics.contact_inertia", "dynamics.kinetic_energy")


def _same(a, b, exact=True) -> bool:
    xa, xb = _arrays_of(a), _arrays_of(b)
    if len(xa) != len(xb):
        return False
    for x, y in zip(xa, xb):
        x, y = np.asarray(x), np.asarray(y)
        if x.shape != y.shape:
            return False
        if exact and x.tobytes() != y.tobytes():
            return False
        if not exact and not np.isclose(x, y, rtol=1e-12, atol=1e-300, equal_nan=True).all():
            return False
    return True


def public_specs(rng):
    """(where, fn, {arg: (valid value maker of lead, kind)}, result shapes of lead, options)."""
    from leg_env.physics import arrays, contact, dynamics, hybrid, integrate
    from leg_env.physics.params import LegParams

    P = LegParams()

    def q(lead):
        x = np.tile(_nominal(), lead + (1,)) + 0.05 * rng.standard_normal(lead + (5,))
        x[..., 1] += 0.002 - dynamics.foot_position(x, P)[..., 1]  # the foot 2 mm above the ground
        return x

    def qd(lead):
        return 0.3 * rng.standard_normal(lead + (5,))

    def tau(lead):
        return 2.0 * rng.standard_normal(lead + (2,))

    def anchor(lead):
        return 0.01 * rng.standard_normal(lead + (2,))

    def scalar(v):
        return lambda lead: v

    Q, QD, TAU, PP = (q, "vec"), (qd, "vec"), (tau, "vec"), (scalar(P), "p")
    HS = hybrid.HybridStep._fields

    def hs_shapes(lead):
        two = ("q", "qd", "lam_mean", "impulse", "event_time", "event_kind")
        tail = {"q": (5,), "qd": (5,), "lam_mean": (2,), "impulse": (2,), "event_time": (16,), "event_kind": (16,)}
        return tuple(lead + tail.get(f, ()) if f in two else lead for f in HS)

    return [
        ("dynamics.mass_matrix", dynamics.mass_matrix, {"q": Q, "p": PP}, lambda L: (L + (5, 5),)),
        ("dynamics.bias_forces", dynamics.bias_forces, {"q": Q, "qd": QD, "p": PP}, lambda L: (L + (5,),)),
        ("dynamics.gravity_forces", dynamics.gravity_forces, {"q": Q, "p": PP}, lambda L: (L + (5,),)),
        ("dynamics.foot_position", dynamics.foot_position, {"q": Q, "p": PP}, lambda L: (L + (2,),)),
        ("dynamics.com_position", dynamics.com_position, {"q": Q, "p": PP}, lambda L: (L + (2,),)),
        ("dynamics.contact_jacobian", dynamics.contact_jacobian, {"q": Q, "p": PP}, lambda L: (L + (2, 5),)),
        ("dynamics.contact_jdot_qd", dynamics.contact_jdot_qd, {"q": Q, "qd": QD, "p": PP}, lambda L: (L + (2,),)),
        ("dynamics.contact_inertia", dynamics.contact_inertia, {"q": Q, "p": PP}, lambda L: (L + (2, 2),)),
        ("dynamics.stance_dynamics", dynamics.stance_dynamics, {"q": Q, "qd": QD, "tau": TAU, "p": PP}, lambda L: (L + (5,), L + (2,))),
        ("dynamics.flight_dynamics", dynamics.flight_dynamics, {"q": Q, "qd": QD, "tau": TAU, "p": PP}, lambda L: (L + (5,),)),
        ("dynamics.kinetic_energy", dynamics.kinetic_energy, {"q": Q, "qd": QD, "p": PP}, lambda L: (L,)),
        ("dynamics.potential_energy", dynamics.potential_energy, {"q": Q, "p": PP}, lambda L: (L,)),
        ("dynamics.static_equilibrium", dynamics.static_equilibrium, {"p": PP, "knee": (scalar(0.8), "knee")}, lambda L: ((5,), (2,), (2,))),
        ("arrays.params_array", arrays.params_array, {"p": PP, "load_x": (scalar(0.0), "load")}, lambda L: ((12,),)),
        ("contact.slip_dynamics", contact.slip_dynamics, {"q": Q, "qd": QD, "tau": TAU, "p": PP, "mu": (scalar(0.8), "mu"),
                                                          "sigma": (scalar(1.0), "sigma")}, lambda L: (L + (5,), L + (2,))),
        ("contact.impact_map", contact.impact_map, {"q": Q, "qd": QD, "p": PP, "mu": (scalar(0.8), "mu_inf")}, lambda L: (L + (5,), L + (2,))),
        ("contact.contact_mode", contact.contact_mode, {"q": Q, "qd": QD, "tau": TAU, "p": PP, "mu": (scalar(0.8), "mu")}, lambda L: (L,)),
        ("contact.free_foot_acceleration", contact.free_foot_acceleration, {"q": Q, "qd": QD, "tau": TAU, "p": PP},
         lambda L: (L + (2, 2), L + (2,))),
        ("contact.mu_critical", contact.mu_critical, {"q": Q, "p": PP}, lambda L: (L,)),
        ("integrate.stance_step", integrate.stance_step, {"q": Q, "qd": QD, "tau": TAU, "p": PP, "dt": (scalar(0.01), "dt"),
                                                          "substeps": (scalar(2), "substeps"), "anchor": (anchor, "vec_none"),
                                                          "max_angle": (scalar(0.02), "max_angle")}, lambda L: (L + (5,), L + (5,), L + (2,))),
        ("integrate.flight_step", integrate.flight_step, {"q": Q, "qd": QD, "tau": TAU, "p": PP, "dt": (scalar(0.01), "dt"),
                                                          "substeps": (scalar(2), "substeps"), "max_angle": (scalar(0.02), "max_angle")},
         lambda L: (L + (5,), L + (5,))),
        ("integrate.project_stance", integrate.project_stance, {"q": Q, "qd": QD, "p": PP, "anchor": (anchor, "vec")},
         lambda L: (L + (5,), L + (5,))),
        ("integrate.project_velocity", integrate.project_velocity, {"q": Q, "qd": QD, "p": PP}, lambda L: (L + (5,),)),
        ("hybrid.hybrid_step", hybrid.hybrid_step, {"q": Q, "qd": QD, "tau": TAU, "p": PP, "mu": (scalar(0.8), "mu"),
                                                    "mode": (scalar(None), "mode"), "anchor_x": (scalar(None), "per_none"),
                                                    "dt": (scalar(0.01), "dt"), "substeps": (scalar(2), "substeps"),
                                                    "max_angle": (scalar(0.02), "max_angle"), "load_x": (scalar(0.0), "load")}, hs_shapes),
    ]


def public_arg_cases(arg, kind, v, lead, rng, n_vec=1):
    """(case, value, expect, canonical float64 value or None (then: compare with it), names) of one argument."""
    nm = (arg,)
    if kind in ("vec", "vec_none"):
        if v.size:  # a list cannot say (0, 5)
            yield "list", v.tolist(), OK, v, nm
            yield "tuple", tuple(map(tuple, v.reshape(-1, v.shape[-1]).tolist())) if v.ndim == 2 else tuple(v.tolist()), OK, v, nm
        yield "int64", np.round(v).astype(np.int64), OK, np.round(v).astype(np.int64).astype(np.float64), nm
        yield "float32", v.astype(np.float32), OK, v.astype(np.float32).astype(np.float64), nm
        yield "float16", v.astype(np.float16), OK, v.astype(np.float16).astype(np.float64), nm
        yield "object of floats", v.astype(object), OK, v, nm
        yield "big-endian", v.astype(">f8"), OK, v, nm
        for label, w in _layouts(v):
            yield label, w, OK, v, nm
        ro = v.copy()
        ro.setflags(write=False)
        yield "read-only", ro, OK, v, nm
        yield "unaligned", _unaligned(v), OK, v, nm
        yield "complex (imaginary part 0)", v.astype(np.complex128), A, v, nm
        yield "complex", v + 1j, R, None, nm
        yield "bool", v > 0, R, None, nm
        yield "numeric strings", v.astype(str), R, None, nm
        yield "str", "abc", R, None, nm
        yield "bytes", b"abcde", R, None, nm
        if v.size:
            o = v.astype(object)
            o.flat[0] = None
            yield "object holding None", o, R, None, nm
        yield "structured", np.zeros(v.shape[:-1], [(f"f{k}", "f8") for k in range(v.shape[-1])]), R, None, nm
        yield "None", None, (OK if kind == "vec_none" else R), None, nm
        yield "python float", 1.0, R, None, nm
        yield "last axis short", v[..., :-1].copy(), R, None, nm
        yield "last axis long", np.concatenate([v, v[..., :1]], axis=-1), R, None, nm
        yield "ragged list", [[0.0] * v.shape[-1], [0.0]], R, None, nm
        if v.ndim > 1 and n_vec > 1 and v.size:
            yield "another batch shape", np.concatenate([v, v]), R, None, "all"
        yield "a trailing axis", v[..., None], R, None, nm
        for val in (NAN, INF, -INF, 1e300, -1e300) if v.size else ():
            w = v.copy()
            w.flat[(w.size * 3) // 7] = val
            yield f"a value {val!r}", w, A, None, nm
        return
    if kind == "p":
        from leg_env.physics.params import LegParams

        a = LegParams().array
        yield "LegParams array", a.copy(), OK, v, nm + ("params",)
        yield "list of 11", a.tolist(), OK, v, nm + ("params",)
        yield "None", None, R, None, nm + ("params",)
        yield "str", "abc", R, None, nm + ("params",)
        yield "dict", {"m_b": 1.0}, R, None, nm + ("params",)
        yield "10 values", a[:10].copy(), R, None, nm + ("params",)
        yield "13 values", np.append(a, [0.0, 0.0]), R, None, nm + ("params",)
        yield "complex", a + 1j, R, None, nm + ("params",)
        yield "(1, 11)", a[None].copy(), A, None, nm + ("params",)
        for j, val in ((0, 0.0), (1, -1.0), (6, NAN), (8, INF), (10, -9.81)):
            w = a.copy()
            w[j] = val
            yield f"array with field {j} = {val!r}", w, R, None, nm + ("params",)
        return
    per = {"mu": (0.8, [(-0.1, R), (NAN, R), (INF, R), (1e300, A), (0.0, OK)]),
           "mu_inf": (0.8, [(-0.1, R), (NAN, R), (INF, OK), (1e300, A), (0.0, OK)]),
           "sigma": (1.0, [(0.0, R), (0.5, R), (2.0, R), (NAN, R), (-1.0, OK)]),
           "load": (0.0, [(NAN, R), (INF, R), (1e300, A), (-5.0, OK)]),
           "mode": (None, [(4, R), (-1, R), (1.5, R), (NAN, R), (True, R), ("1", R), (3, A), (0, A)]),
           "per_none": (None, [(NAN, A), (INF, A), (1e300, A), ("x", R), (1 + 1j, R)]),
           "knee": (0.8, [(NAN, A), (INF, A), (1e300, A), ("x", R), (None, R), (1 + 1j, R), ([0.8, 0.9], R), (True, R)]),
           "dt": (0.01, [(0.0, R), (-1.0, R), (NAN, R), (INF, R), ("0.01", R), (None, R), (1 + 1j, R), (True, R), (1e300, A)]),
           "substeps": (2, [(0, R), (4097, R), (2.5, R), (-1, R), (NAN, R), ("2", R), (None, R), (True, R), (4096, A), (2.0, A)]),
           "max_angle": (0.02, [(0.0, R), (-1.0, R), (NAN, R), ("x", R), (None, R), (INF, A), (1e-300, A)])}[kind]
    for val, expect in per[1]:
        if lead == (0,) and kind in ("mu", "mu_inf", "sigma", "load", "mode", "per_none") and expect == R and not isinstance(val, (str, bool, complex)):
            expect = A  # no robot reads it
        yield f"value {val!r}", val, expect, None, nm
    if kind in ("mu", "mu_inf", "sigma", "load", "per_none", "mode") and lead:
        base = {"mode": 1, "per_none": 0.0}.get(kind, per[0] if per[0] is not None else 0.0)
        arr = np.full(lead, base, dtype=np.int64 if kind == "mode" else np.float64)
        yield "per robot", arr, A, None, nm
        if arr.size:
            yield "per robot, one short", arr.reshape(-1)[:-1].copy(), R, None, nm
        yield "per robot, strided", _strided(arr.astype(np.float64)) if kind != "mode" else _strided(arr), A, None, nm
        yield "per robot, complex", arr + 1j, R, None, nm
        yield "per robot, bool", np.ones(lead, bool), R, None, nm
        yield "per robot, strings", arr.astype(str), R, None, nm


def fuzz_public(run, module, rng):
    """Every argument of every public function of ``module`` made bad in turn, single robot and batched."""
    for where, fn, argspec, shapes in public_specs(rng):
        if not where.startswith(module + "."):
            continue
        for lead in ((), (3,), (2, 2), (0,)):
            if lead and not any(kind.startswith("vec") for _, kind in argspec.values()):
                continue
            base = {name: make(lead) for name, (make, kind) in argspec.items()}
            expected = shapes(lead)
            kinds = {name: kind for name, (make, kind) in argspec.items()}

            def check_of(extreme, allow_inf=where.endswith("mu_critical")):
                def check(result):
                    if where.endswith("hybrid_step"):
                        got = tuple(np.shape(getattr(result, f)) for f in result._fields)
                    else:
                        got = _shapes(result)
                    if got != expected:
                        return f"shapes {got}, expected {expected}"
                    if not extreme and not allow_inf:
                        for x in _arrays_of(result):
                            x = np.asarray(x)
                            if x.dtype.kind == "f" and np.isinf(x).any():
                                return "an infinite output from moderate inputs"
                    return None

                return check

            ref = run.case(where, "(all)", f"valid, lead {lead}", fn, kwargs=dict(base), expect=OK, check=check_of(False))
            for arg, (make, kind) in argspec.items():
                v = base[arg]
                n_vec = sum(k == "vec" for k in kinds.values())
                for case, w, expect, canon, nm in public_arg_cases(arg, kind, v, lead, rng, n_vec):
                    if nm == "all":
                        nm = tuple(a for a, k in kinds.items() if k.startswith("vec"))
                    kw = dict(base)
                    kw[arg] = w
                    extreme = "value" in case or "complex" in case or "int64" in case or "float16" in case or "per robot" in case
                    check = check_of(extreme)
                    if canon is not None and ref is not None:
                        kw_c = dict(base)
                        kw_c[arg] = canon
                        with warnings.catch_warnings():
                            warnings.simplefilter("ignore")
                            try:
                                want = fn(**kw_c)
                            except Exception:  # noqa: BLE001 - reported by its own case
                                want = None

                        def check(result, want=want, inner=check):
                            bad = inner(result)
                            if bad or want is None:
                                return bad
                            if where.endswith("hybrid_step"):
                                same = all(np.asarray(getattr(result, f)).tobytes() == np.asarray(getattr(want, f)).tobytes() for f in result._fields)
                            else:
                                same = _same(result, want, exact=where not in NUMPY_TAIL)
                            return None if same else "differs from the float64 C-ordered array's result"

                    run.case(where, arg, f"{case} (lead {lead})", fn, kwargs=kw, expect=expect, names=nm, check=check)


def _dt_rule(v):
    return (A if v > 1e10 else OK) if 0 < v < INF else R


def _steps_rule(v):
    return OK if (1 <= v <= 4096 and v == math.floor(v)) else R


def _angle_rule(v):
    return A if v > 0 else R


def fuzz_step_inplace(run, rng):
    """integrate.step_inplace: the in-place public step (its arrays are the kernel's)."""
    from leg_env.physics import integrate
    from leg_env.physics.params import LegParams

    where = "integrate.step_inplace"
    P = LegParams().array
    names = ("q", "qd", "tau", "p", "anchor", "dt", "substeps", "max_angle", "stance", "lam_mean")

    def valid(n=3):
        q, qd, tau = _robots(rng, n)
        return [q, qd, tau, P.copy(), 0.01 * rng.standard_normal((n, 2)), 0.01, 2, 0.02, True, _filled((n, 2))]

    args = valid()
    run.case(where, "(all)", "valid", integrate.step_inplace, args, expect=OK, outs=[args[9]], inputs=[args[2], args[4]])
    roles = {"q": "inout", "qd": "inout", "tau": "in", "anchor": "in", "lam_mean": "out"}
    for pos, arg in enumerate(names):
        v = valid()[pos]
        if arg in roles:
            cases = array_cases(arg, v, roles[arg], DTYPES_F8, defining=arg == "q", all_names=("q", "qd", "tau", "anchor", "lam_mean", "load"))
        elif arg == "p":
            cases = [("12 values (a load)", np.append(P, 5.0), OK, ("p",)), ("10 values", P[:10].copy(), R, ("p",)),
                     ("(1, 11)", P[None].copy(), R, ("p",)), ("None", None, R, ("p",)), ("str", "abc", R, ("p",)),
                     ("complex", P + 1j, R, ("p",)), ("mass 0", np.where(np.arange(11) == 0, 0.0, P), R, ("p",)),
                     ("g NaN", np.where(np.arange(11) == 10, NAN, P), R, ("p",)), ("load NaN", np.append(P, NAN), A, ("p", "load"))]
        elif arg == "dt":
            cases = scalar_cases(arg, _dt_rule, [0.01, 0.0, -1.0, NAN, INF])
        elif arg == "substeps":
            cases = scalar_cases(arg, _steps_rule, [2, 0, 4097, 2.5])
        elif arg == "max_angle":
            cases = scalar_cases(arg, _angle_rule, [0.02, 0.0, NAN, INF])
        else:
            cases = flag_cases(arg)
        for kind, w, expect, nm in cases:
            args = valid()
            args[pos] = w
            if arg == "q" and expect == R and kind in ("one value short", "one value long"):
                nm = ("q", "qd", "tau", "anchor", "lam_mean", "load")
            run.case(where, arg, kind, integrate.step_inplace, args, expect=expect, names=nm)
    args = valid()
    args[1] = args[0]  # q as qd: the state would be overwritten while it is read
    run.case(where, "qd", "the same array as q", integrate.step_inplace, args, expect=R, names=("q", "qd"))
    args = valid()
    args[9] = args[2][:, :2] if args[2].flags.c_contiguous else args[9]  # lam_mean written over tau
    run.case(where, "lam_mean", "the same array as tau", integrate.step_inplace, args, expect=R, names=("tau", "lam_mean"))


# ------------------------------------------------------------------------------------------------ envs
def _env_snapshot(env, wrappers=True):
    """The env's arrays, generators and counters (and its wrappers' step counters: not for a reset, which
    Gymnasium's TimeLimit zeroes before it calls the env's reset)."""
    u = env.unwrapped
    arrays = [u._state, u._out, u._obs, u._robots, u._settings]
    parts = [_bits(a) for a in arrays]
    rng = getattr(u, "_np_random", None)
    if rng is not None:
        parts.append(json.dumps(rng.bit_generator.state, default=str))
    if hasattr(u, "_rngs"):
        parts.append([json.dumps(g.bit_generator.state, default=str) if g is not None else None for g in u._rngs.generators])
    for attr in ("_elapsed", "_ended", "_needs_reset"):
        if hasattr(u, attr):
            parts.append(_bits(np.asarray(getattr(u, attr))))
    w = env
    while wrappers and hasattr(w, "env"):
        if hasattr(w, "_elapsed_steps"):
            parts.append(w._elapsed_steps)
        w = w.env
    return parts


BAD_ACTIONS = [
    ("None", None), ("str", "ab"), ("bytes", b"ab"), ("python float", 0.5), ("one value", [0.1]), ("three values", [0.1, 0.2, 0.3]),
    ("(2, 1)", np.zeros((2, 1))), ("(1, 2)", np.zeros((1, 2))), ("NaN hip", [NAN, 0.0]), ("inf knee", [0.0, INF]), ("-inf", [-INF, 0.0]),
    ("complex", np.array([0.1 + 1j, 0.0])), ("bools", [True, False]), ("bool array", np.array([True, False])),
    ("numeric strings", np.array(["0.1", "0.2"])), ("object with None", np.array([0.1, None], dtype=object)),
    ("structured", np.zeros(2, [("x", "f8")])), ("dict", {"a": 1}), ("ragged", [[0.1], 0.2]),
]
GOOD_ACTIONS = [("float32", np.array([0.1, -0.2], np.float32)), ("list", [0.1, 0.2]), ("huge (clipped)", [1e300, -1e300]),
                ("int array", np.array([1, 0])), ("big-endian", np.array([0.1, 0.2], ">f8")), ("strided", _strided(np.array([0.1, 0.2]))),
                ("read-only", np.array([0.1, 0.2])), ("tuple", (0.3, 0.4))]
GOOD_ACTIONS[-2][1].setflags(write=False)


def bad_reset_options(n=None):
    shape5 = (5,) if n is None else (n, 5)
    cases = [
        ("options a str", dict(options="x"), ("options",)), ("an unknown option", dict(options={"bogus": 1}), ("option", "bogus")),
        ("qpos a str", dict(options={"qpos": "abc"}), ("qpos",)), ("qpos NaN", dict(options={"qpos": np.full(shape5, NAN)}), ("qpos",)),
        ("qpos (4,)", dict(options={"qpos": np.zeros(4)}), ("qpos",)), ("qpos 1e300", dict(options={"qpos": np.full(shape5, 1e300)}), ("qpos",)),
        ("qpos complex", dict(options={"qpos": np.zeros(shape5) + 1j}), ("qpos",)), ("qpos bools", dict(options={"qpos": np.ones(shape5, bool)}), ("qpos",)),
        ("qpos structured", dict(options={"qpos": np.zeros(5, [("x", "f8")])}), ("qpos",)), ("qpos None", dict(options={"qpos": None}), ("qpos",)),
        ("qpos ragged", dict(options={"qpos": [[0.0], 1.0]}), ("qpos",)), ("qvel inf", dict(options={"qvel": np.full(shape5, INF)}), ("qvel",)),
        ("qvel 1e300", dict(options={"qvel": np.full(shape5, 1e300)}), ("qvel",)), ("qvel strings", dict(options={"qvel": ["0"] * 5}), ("qvel",)),
        ("params a str", dict(options={"params": "x"}), ("params",)), ("params m_b -1", dict(options={"params": {"m_b": -1.0}}), ("m_b", "params")),
        ("params m_b NaN", dict(options={"params": {"m_b": NAN}}), ("m_b", "params")),
        ("params an unknown field", dict(options={"params": {"bogus": 1.0}}), ("bogus", "params")),
        ("params l1 inf", dict(options={"params": {"l1": INF}}), ("l1", "params")),
        ("seed -1", dict(seed=-1), ("seed", "seeds")), ("seed 1.5", dict(seed=1.5), ("seed", "seeds")), ("seed str", dict(seed="x"), ("seed", "seeds")),
        ("seed True", dict(seed=True), ("seed", "seeds")), ("seed a list", dict(seed=[1]), ("seed", "seeds")),
    ]
    if n is not None:
        cases += [("reset_mask ints", dict(options={"reset_mask": np.ones(n, int)}), ("reset_mask",)),
                  ("reset_mask short", dict(options={"reset_mask": np.ones(n - 1, bool)}), ("reset_mask",)),
                  ("reset_mask none set", dict(options={"reset_mask": np.zeros(n, bool)}), ("reset_mask",)),
                  ("reset_mask a list", dict(options={"reset_mask": [True] * n}), ("reset_mask",)),
                  ("seed list short", dict(seed=[1] * (n - 1)), ("seed", "seeds")), ("seed list with -1", dict(seed=[1] * (n - 1) + [-1]), ("seed", "seeds"))]
    return cases


def fuzz_envs(run, rng):
    import gymnasium as gym
    import leg_env

    for env_id in leg_env.ENV_IDS:
        where = f"env[{env_id}]"
        env = gym.make(env_id)
        run.case(where + ".reset", "(all)", "valid", env.reset, kwargs={"seed": 0}, expect=OK)
        run.case(where + ".step", "action", "valid", env.step, [np.array([0.1, 0.1])], expect=OK)
        for kind, a in BAD_ACTIONS:
            run.case(where + ".step", "action", kind, env.step, [a], expect=R, names=("action",), watch=lambda env=env: _env_snapshot(env))
        for kind, a in GOOD_ACTIONS:
            run.case(where + ".step", "action", kind, env.step, [a], expect=OK)
        for kind, kw, nm in bad_reset_options():
            run.case(where + ".reset", "options/seed", kind, env.reset, kwargs=kw, expect=R, names=nm,
                     watch=lambda env=env: _env_snapshot(env, wrappers=False))
        run.case(where + ".reset", "options", "qpos and qvel", env.reset, kwargs={"options": {"qpos": _nominal(), "qvel": np.zeros(5)}}, expect=OK)
        for k in range(25):  # a random walk, reset when it ends
            result = run.case(where + ".step", "(walk)", f"step {k}", env.step, [rng.uniform(-1, 1, 2)], expect=OK)
            if result is not None and (result[2] or result[3]):
                env.reset()
        env.close()

        n = 3
        venv = gym.make_vec(env_id, num_envs=n, vectorization_mode="vector_entry_point")
        where = f"vector env[{env_id}]"
        run.case(where + ".reset", "(all)", "valid", venv.reset, kwargs={"seed": 0}, expect=OK)
        good = np.zeros((n, 2))
        run.case(where + ".step", "actions", "valid", venv.step, [good], expect=OK)
        bad = [("None", None), ("str", "ab"), ("(n,)", np.zeros(n)), ("(2, 2)", np.zeros((2, 2))), ("(n, 3)", np.zeros((n, 3))),
               ("NaN in a row", np.where(np.arange(2 * n).reshape(n, 2) == 3, NAN, 0.0)), ("inf", np.full((n, 2), INF)),
               ("complex", np.zeros((n, 2)) + 1j), ("bools", np.ones((n, 2), bool)), ("strings", np.zeros((n, 2)).astype(str)),
               ("object with None", np.array([[None, 0.0]] * n, dtype=object)), ("structured", np.zeros(n, [("a", "f8"), ("b", "f8")])),
               ("(n, 2, 1)", np.zeros((n, 2, 1))), ("ragged list", [[0.0, 0.0]] * (n - 1) + [[0.0]])]
        for kind, a in bad:
            run.case(where + ".step", "actions", kind, venv.step, [a], expect=R, names=("actions", "action"),
                     watch=lambda venv=venv: _env_snapshot(venv))
        for kind, a in (("float32", np.zeros((n, 2), np.float32)), ("list", [[0.1, 0.2]] * n), ("fortran order", np.asfortranarray(np.zeros((n, 2)))),
                        ("strided", _strided(np.zeros((n, 2)))), ("int", np.zeros((n, 2), int)), ("huge (clipped)", np.full((n, 2), 1e300))):
            run.case(where + ".step", "actions", kind, venv.step, [a], expect=OK)
        for kind, kw, nm in bad_reset_options(n):
            run.case(where + ".reset", "options/seed", kind, venv.reset, kwargs=kw, expect=R, names=nm,
                     watch=lambda venv=venv: _env_snapshot(venv, wrappers=False))
        mask = np.array([True, False, True])
        run.case(where + ".reset", "options", "reset_mask", venv.reset, kwargs={"options": {"reset_mask": mask}}, expect=OK)
        for k in range(15):
            run.case(where + ".step", "(walk)", f"step {k}", venv.step, [rng.uniform(-1, 1, (n, 2))], expect=OK)
        venv.close()


# ------------------------------------------------------------------------------------------------ groups
def group_kernels_physics(run, rng):
    """Every entry point of the module's table but the two steps (group_kernels_steps), from its signature."""
    for name, spec in kernel_specs().items():
        if name in STEPS:
            continue
        one_row = not any(a.rows == "N" for a in spec)
        for n in ((1,) if one_row else (0, 1, 3)):
            fuzz_kernel(run, name, spec, rng, n, variants=n == 3 or one_row)
        fuzz_kernel_random(run, name, spec, rng, 60)


STEPS = ("rk4_step", "hybrid_step")


def group_kernels_steps(run, rng):
    specs = kernel_specs()
    for name in STEPS:
        for n in (0, 1, 3):
            fuzz_kernel(run, name, specs[name], rng, n, variants=n == 3)
        fuzz_kernel_random(run, name, specs[name], rng, 500)


def group_kernels_packed(run, rng):
    import leg_env

    for env_id in leg_env.ENV_IDS:
        fuzz_packed(run, env_id, rng)
        fuzz_packed_scalars(run, env_id, rng)
        fuzz_packed_random(run, env_id, rng, 250)


def group_kernels_batch(run, rng):
    import leg_env

    for env_id in leg_env.ENV_IDS:
        fuzz_batch(run, env_id, rng)


def group_kernels_draws(run, rng):
    fuzz_draws(run, rng)


def group_public_dynamics(run, rng):
    fuzz_public(run, "dynamics", rng)


def group_public_contact(run, rng):
    fuzz_public(run, "contact", rng)


def group_public_integrate(run, rng):
    fuzz_public(run, "integrate", rng)
    fuzz_public(run, "hybrid", rng)
    fuzz_step_inplace(run, rng)


def group_envs(run, rng):
    fuzz_envs(run, rng)


GROUPS = ("kernels_physics", "kernels_steps", "kernels_packed", "kernels_batch", "kernels_draws", "public_dynamics", "public_contact",
          "public_integrate", "envs")


def child_main(group: str, log_path: str, result_path: str) -> None:
    import faulthandler

    faulthandler.enable()
    faulthandler.dump_traceback_later(GROUP_TIMEOUT - 5, exit=True)  # a hang: the Python stack, then exit 1
    sys.path.insert(0, ROOT)
    run = Run(log_path)
    rng = np.random.default_rng(int(os.environ.get("LEG_ENV_FUZZ_SEED", "0")) * 1000003 + sum(map(ord, group)))
    t0 = time.perf_counter()
    globals()[f"group_{group}"](run, rng)
    with open(result_path, "w") as fh:
        json.dump({"problems": run.problems, "cases": run.cases, "seconds": time.perf_counter() - t0,
                   "slowest": sorted(run.slowest, reverse=True)[:10]}, fh)


# ================================================================================================ pytest
def _known(problem: dict) -> str | None:
    for (where, arg, kind), why in KNOWN.items():
        if fnmatch.fnmatchcase(problem["where"], where) and fnmatch.fnmatchcase(problem["arg"], arg) and fnmatch.fnmatchcase(problem["kind"], kind):
            return why
    return None


def _show(problems, limit=60) -> str:
    lines = [f"  {p['where']} | {p['arg']} | {p['kind']}: {p['what']}" + (f" -- {p['detail']}" if p["detail"] else "") for p in problems[:limit]]
    if len(problems) > limit:
        lines.append(f"  ... and {len(problems) - limit} more")
    return "\n".join(lines)


def run_group(group: str, tmp_dir: str) -> dict:
    """Run one group in a child process; a crash or a hang is reported with the case it was in."""
    log_path, result_path = os.path.join(tmp_dir, f"{group}.log"), os.path.join(tmp_dir, f"{group}.json")
    env = dict(os.environ, SDL_VIDEODRIVER="dummy", SDL_AUDIODRIVER="dummy", OMP_NUM_THREADS="1", PYTHONFAULTHANDLER="1",
               MALLOC_CHECK_="3", MALLOC_PERTURB_="165")  # glibc: freed and fresh heap memory filled, heap checks on
    try:
        proc = subprocess.run([sys.executable, os.path.abspath(__file__), group, log_path, result_path], cwd=ROOT, env=env,
                              capture_output=True, text=True, timeout=GROUP_TIMEOUT)
        code, stderr = proc.returncode, proc.stderr
    except subprocess.TimeoutExpired as e:
        code, stderr = "timeout", (e.stderr or b"").decode(errors="replace") if isinstance(e.stderr, bytes) else (e.stderr or "")
    if code != 0 or not os.path.exists(result_path):
        lines = []
        if os.path.exists(log_path):
            with open(log_path) as fh:
                lines = fh.read().splitlines()
        last = lines[-1] if lines else "(none)"
        before = "\n".join(f"    {line}" for line in lines[-6:-1])  # heap damage is often found a few cases after it was done
        return {"crash": f"the child exited with {code} (signal {-code if isinstance(code, int) and code < 0 else '-'}) in the case\n  {last}\n"
                         f"  after the cases\n{before}\nstderr:\n{stderr[-4000:]}"}
    with open(result_path) as fh:
        return json.load(fh)


DEAD_CAPSULE = """
import gc, numpy as np
from leg_env._core import kernels
capsules = [np.random.PCG64(k).capsule for k in range(8)]  # each BitGenerator is freed at once
gc.collect()
generators = kernels.Generators(8)
for k, capsule in enumerate(capsules):
    generators.set(k, capsule)
kernels.draw_uniform(generators, np.arange(8, dtype=np.int64), np.zeros((8, 2)))
"""

if __name__ == "__main__":
    child_main(*sys.argv[1:4])
else:
    import pytest

    @pytest.mark.parametrize("group", GROUPS)
    def test_fuzz(group, tmp_path):
        result = run_group(group, str(tmp_path))
        assert "crash" not in result, f"{group}: {result.get('crash')}"
        problems = result["problems"]
        new = [p for p in problems if _known(p) is None]
        known = [p for p in problems if _known(p) is not None]
        if known:
            reasons: dict[str, int] = {}
            for p in known:
                reasons[_known(p)] = reasons.get(_known(p), 0) + 1
            lines = "\n".join(f"  {count:4d} x {why}" for why, count in sorted(reasons.items(), key=lambda kv: -kv[1]))
            warnings.warn(f"{group}: {len(known)} cases hit known Python-side problems (KNOWN):\n{lines}", stacklevel=1)
        assert not new, f"{group}: {len(new)} problem(s) in {result['cases']} cases:\n{_show(new)}"
        assert result["cases"] > 100, f"{group}: only {result['cases']} cases ran"

    def test_capsule_of_a_freed_generator():
        env = dict(os.environ, PYTHONMALLOC="debug")  # freed memory is overwritten: the read fails for certain
        proc = subprocess.run([sys.executable, "-c", DEAD_CAPSULE], cwd=ROOT, env=env, capture_output=True, text=True, timeout=60)
        assert proc.returncode == 1 and ("ValueError" in proc.stderr or "TypeError" in proc.stderr), proc.stderr[-2000:]
