"""Command lines from argument dataclasses: one option per field, its docstring as the help text.

A field's docstring is the string literal written under it (PEP 257's attribute docstring), read
from the class source once, so the dataclass is the single place that documents an argument. A
dataclass that extends another (``train.ppo.TrainArgs`` extends ``train.run.RunArgs``) has the base's
fields and docstrings, its own where it declares a field again. An option that was renamed is listed in
the class's ``RENAMED`` (``{old field name: new field name}``): the old option is an error that names the new.
"""

from __future__ import annotations

import argparse
import ast
import dataclasses
import inspect
import textwrap
import types
import typing
from pathlib import Path

__all__ = ["field_docs", "parser_for", "parse_args", "interrupt"]


def field_docs(cls: type) -> dict[str, str]:
    """``{field name: docstring}`` for the attribute docstrings of a dataclass and of the dataclasses it extends."""
    docs = {}
    for klass in reversed(cls.__mro__):
        if dataclasses.is_dataclass(klass):
            docs.update(_own_field_docs(klass))
    return docs


def _own_field_docs(cls: type) -> dict[str, str]:
    """``{field name: docstring}`` for the attribute docstrings in the body of the class ``cls``."""
    tree = ast.parse(textwrap.dedent(inspect.getsource(cls)))
    body = tree.body[0].body
    docs = {}
    for node, after in zip(body, body[1:]):
        if (
            isinstance(node, ast.AnnAssign)
            and isinstance(node.target, ast.Name)
            and isinstance(after, ast.Expr)
            and isinstance(after.value, ast.Constant)
            and isinstance(after.value.value, str)
        ):
            docs[node.target.id] = " ".join(after.value.value.split())
    return docs


def _base_type(tp):
    """``int`` for ``int | None``; the type itself otherwise."""
    if typing.get_origin(tp) in (typing.Union, types.UnionType):
        args = [a for a in typing.get_args(tp) if a is not type(None)]
        if len(args) == 1:
            return args[0]
    return tp


def parser_for(cls: type, positional: tuple[str, ...] = (), **parser_kwargs) -> argparse.ArgumentParser:
    """An ``ArgumentParser`` with one option per field of ``cls`` (``--snake-case``; bools get ``--no-...``).

    Fields named in ``positional`` become positional arguments (optional when they have a default).
    """
    doc = inspect.getdoc(cls) or ""
    parser = argparse.ArgumentParser(
        description=doc.split("\n\n")[0], formatter_class=argparse.ArgumentDefaultsHelpFormatter, **parser_kwargs
    )
    docs = field_docs(cls)
    hints = typing.get_type_hints(cls)
    for f in dataclasses.fields(cls):
        tp = _base_type(hints[f.name])
        kwargs: dict = {"help": docs.get(f.name, "").replace("%", "%%")}  # argparse %-formats help texts
        if f.default is not dataclasses.MISSING:
            kwargs["default"] = f.default
        elif f.default_factory is not dataclasses.MISSING:
            kwargs["default"] = f.default_factory()
        elif f.name not in positional:
            kwargs["required"] = True  # no default: a required option (a positional one is required anyway)
        if tp is bool:
            kwargs["action"] = argparse.BooleanOptionalAction
        elif typing.get_origin(tp) is list:
            kwargs["nargs"] = "*"
            kwargs["type"] = typing.get_args(tp)[0]
            kwargs["metavar"] = f.name.upper()
        else:
            kwargs["type"] = tp if tp in (int, float, str, Path) else str
        if f.name in positional:
            kwargs.pop("action", None)
            if f.default is not dataclasses.MISSING:
                kwargs["nargs"] = "?"
            parser.add_argument(f.name, **kwargs)
        else:
            parser.add_argument(_option(f.name), dest=f.name, **kwargs)
    for old, new in getattr(cls, "RENAMED", {}).items():
        parser.add_argument(_option(old), nargs="?", action=_renamed(_option(new)), default=argparse.SUPPRESS, help=argparse.SUPPRESS)
    return parser


def _option(name: str) -> str:
    """The command-line option of the field ``name``: ``--snake-case``."""
    return "--" + name.replace("_", "-")


def _renamed(new: str) -> type[argparse.Action]:
    """An argparse action that refuses an option, saying it was renamed ``new``."""

    class Renamed(argparse.Action):
        def __call__(self, parser, namespace, values, option_string=None):
            parser.error(f"{option_string} was renamed {new}")

    return Renamed


def parse_args(cls: type, argv: list[str] | None = None, positional: tuple[str, ...] = (), prog: str | None = None):
    """Parse ``argv`` (default: ``sys.argv[1:]``) into an instance of the dataclass ``cls``.

    A ``ValueError`` from the dataclass's own validation (``__post_init__``) is reported like any
    other bad argument: usage and message on stderr, exit status 2.
    """
    parser = parser_for(cls, positional, prog=prog)
    ns = parser.parse_args(argv)
    try:
        return cls(**vars(ns))
    except ValueError as e:
        parser.error(str(e))


def interrupt(signum, frame):
    """A signal handler that raises ``KeyboardInterrupt``: installed for SIGTERM, a ``kill`` stops a command as a
    Ctrl-C does (training saves a checkpoint and exits with 130)."""
    raise KeyboardInterrupt
