"""The compiled core: the planar leg's dynamics, contact and time stepping in C.

``kernels`` is the extension module built from ``module.c`` (and the files it includes: ``fields.h``, ``robot.h`` and
``env.h`` the structs, written once as field lists; ``dynamics.c``, ``contact.c``, ``integrate.c``, ``hybrid.c`` the
physics; ``env.c``, ``tasks.c``, ``draws.c`` the environments; ``hopper.c`` the hopping controller's law
(``policies.hopper``); ``plan.c`` the model-predictive controllers' plan and backward pass (``policies.ilqr``);
``calls.c`` each entry point's work; ``objects.c`` its two types) by the package's build
backend at install. Nothing is compiled at run time. Its functions take numpy arrays and loop over robots in C with
the GIL released; ``signatures()`` says what each takes. The public API (``leg_env.physics``) shapes the arrays
around them, and ``leg_env.physics.layout`` builds the numpy dtypes of the C structs from the layouts the module
reports.
"""

from . import kernels

__all__ = ["kernels", "signatures"]

_DTYPES = {"d": "float64", "P": "float64 (leg_params)", "q": "int64", "f": "float32", "?": "bool", "R": "leg_record", "S": "env_state",
           "B": "env_robot", "C": "env_settings", "O": "env_out", "r": "real", "i": "integer", "l": "flag", "g": "object"}
_ROLES = {"i": "in", "o": "out", "u": "inout"}
_OPT_NONE, _OPT_WHOLE, _OPT_OPEN = 1, 2, 4


def signatures() -> dict:
    """Every entry point of ``kernels``, as the binder that fetches and checks its arguments reads it.

    ``{name: {"doc", "releases_gil", "answers", "args"}}``; each argument is a dict: ``name``; ``dtype`` (an array's
    numpy type or struct, or ``real``, ``integer``, ``flag``, ``object``) and its one-letter ``kind``; ``rows``, the
    shape rule of an array (``N`` one row per robot, the first such array setting N; ``M`` one row shared by every
    robot or one per robot; ``1`` one row; ``*`` any number; ``T`` any number of blocks of N rows); ``width``, its
    values per row (0: a 2-d array's own columns); ``itemsize``; ``role`` (``in``, ``out``, ``inout``); ``range``, the
    accepted values of a number or of an integer array's entries (None: any), ``open`` (the low end excluded) and
    ``whole`` (whole numbers only); ``optional`` (None is accepted). Read from the module's own table, so that a new
    entry point is described (and fuzzed, ``tests/test_fuzz_core.py``) without a line written elsewhere.
    """
    out = {}
    for name, (doc, release, answers, args) in kernels.table().items():
        rows = [{"name": a, "kind": kind, "dtype": _DTYPES[kind], "rows": rule.strip(), "role": _ROLES[role], "width": width, "itemsize": size,
                 "range": None if lo > hi else (lo, hi), "optional": bool(opts & _OPT_NONE), "whole": bool(opts & _OPT_WHOLE),
                 "open": bool(opts & _OPT_OPEN)} for a, kind, rule, role, width, size, lo, hi, opts in args]  # fmt: skip
        out[name] = {"doc": doc, "releases_gil": bool(release), "answers": bool(answers), "args": tuple(rows)}
    return out
