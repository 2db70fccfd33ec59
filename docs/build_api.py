"""Build the API reference ``docs/api.md`` from the docstrings of softplan_jax's public names.

::

    python docs/build_api.py            # (re)write docs/api.md
    python docs/build_api.py --check    # exit 1 if docs/api.md is not up to date

The public names are ``softplan_jax.__all__`` when the package declares it,
else every name of the package namespace that softplan_jax defines (functions,
classes, jitted functions) or that is plain data (constants). They are grouped
by the module that defines them, in the order of ``__all__`` (else by name).

Exit code 1, with the names listed on stderr, when a public function or class
has no docstring of its own (a class must have its own ``__doc__``: the
automatic ``Gains(k_att, ...)`` of a NamedTuple does not count). Constants
cannot carry a docstring and are listed with their value. Public methods and
properties of public classes are listed too, with their docstrings when they
have one.

Only the standard library (``inspect``) and softplan_jax are used: no
documentation framework to install.
"""

from __future__ import annotations

import argparse
import enum
import inspect
import os
import re
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(HERE)
API_MD = os.path.join(HERE, "api.md")


def _package():
    sys.path.insert(0, REPO)
    import softplan_jax

    return softplan_jax


def _is_data(obj) -> bool:
    return not (inspect.isclass(obj) or callable(obj) or inspect.ismodule(obj))


def public_names(pkg) -> list[str]:
    """``pkg.__all__``, else the package's own public functions/classes and its constants."""
    if hasattr(pkg, "__all__"):
        return [n for n in pkg.__all__ if n != "__version__"]
    out = []
    for name, obj in sorted(vars(pkg).items()):
        if name.startswith("_") or inspect.ismodule(obj):
            continue
        module = getattr(obj, "__module__", None) or ""
        if _is_data(obj) or module.split(".")[0] == pkg.__name__:
            out.append(name)
    return out


def own_doc(obj) -> str | None:
    """The object's own docstring (cleaned), or None: inherited and generated ones do not count."""
    if inspect.isclass(obj):
        doc = obj.__dict__.get("__doc__")
        fields = getattr(obj, "_fields", None)
        if doc and fields is not None and doc.startswith(f"{obj.__name__}("):  # NamedTuple's generated doc
            doc = None
    else:
        doc = getattr(obj, "__doc__", None)
    return inspect.cleandoc(doc) if doc and doc.strip() else None


def missing_docstrings(pkg) -> list[str]:
    """Public functions and classes without a docstring of their own."""
    return [n for n in public_names(pkg) if not _is_data(getattr(pkg, n)) and own_doc(getattr(pkg, n)) is None]


def _clean(text: str) -> str:
    """Remove what changes from run to run (object addresses)."""
    return re.sub(r" at 0x[0-9a-fA-F]+", "", text)


def _signature(obj) -> str:
    """``(a, b=1, *, c=None)``: parameters and defaults, annotations left out
    (they are in the docstrings, and their repr changes between Python versions)."""
    try:
        sig = inspect.signature(obj)
    except (TypeError, ValueError):
        return "(...)"
    sig = sig.replace(
        parameters=[p.replace(annotation=inspect.Parameter.empty) for p in sig.parameters.values()],
        return_annotation=inspect.Signature.empty,
    )
    return _clean(str(sig))


def _doc_block(doc: str | None) -> list[str]:
    if doc is None:
        return ["*(no docstring)*", ""]
    return ["```text", doc, "```", ""]


def _members(cls) -> list[tuple[str, str, str | None]]:
    """(name, signature or 'property', docstring) of the public methods and properties defined in cls."""
    out = []
    for name, attr in cls.__dict__.items():
        if name.startswith("_") or name in getattr(cls, "_fields", ()) or name in _PROTOCOL:
            continue
        if isinstance(attr, property):
            out.append((name, "property", inspect.getdoc(attr)))
        elif isinstance(attr, (staticmethod, classmethod)):
            fn = attr.__func__
            out.append((name, _signature(fn), own_doc(fn)))
        elif inspect.isfunction(attr):
            out.append((name, _signature(attr), own_doc(attr)))
    return out


# pytree protocol methods: public by name, not part of the user's API
_PROTOCOL = {"tree_flatten", "tree_unflatten"}

# Modules in the order data flows through the library (DESIGN.md); others after, by name.
_MODULE_ORDER = [
    "kinematics", "curves", "closest", "obstacles", "scenarios", "planner", "metrics", "tuning", "plotting",
]


def _module_rank(module: str, pkg_name: str):
    short = module[len(pkg_name) + 1 :] if module.startswith(pkg_name + ".") else ""
    head = short.split(".")[0]
    rank = _MODULE_ORDER.index(head) if head in _MODULE_ORDER else len(_MODULE_ORDER)
    return (module == pkg_name, rank, module)


def _entry(name: str, obj) -> list[str]:
    if _is_data(obj):
        value = _clean(repr(obj))
        if len(value) > 300:
            value = value[:300] + " ..."
        return [f"### `{name}`", "", "Constant:", "", "```python", f"{name} = {value}", "```", ""]
    if inspect.isclass(obj):
        lines = [f"### class `{name}{_signature(obj)}`", ""]
        lines += _doc_block(own_doc(obj))
        if issubclass(obj, enum.Enum):
            lines += ["Members: " + ", ".join(f"`{m.name}` = {m.value!r}" for m in obj), ""]
        fields = getattr(obj, "_fields", None)
        if fields:
            lines += ["Fields: " + ", ".join(f"`{f}`" for f in fields), ""]
        for mname, sig, doc in _members(obj):
            head = f"`{name}.{mname}`" if sig == "property" else f"`{name}.{mname}{sig}`"
            lines += [f"#### {head}" + (" (property)" if sig == "property" else ""), ""]
            if doc is not None:
                lines += _doc_block(doc)
        return lines
    return [f"### `{name}{_signature(obj)}`", ""] + _doc_block(own_doc(obj))


def render(pkg=None) -> str:
    """The text of docs/api.md."""
    pkg = pkg or _package()
    names = public_names(pkg)
    groups: dict[str, list[str]] = {}
    for name in names:
        obj = getattr(pkg, name)
        module = pkg.__name__ if _is_data(obj) else (getattr(obj, "__module__", None) or pkg.__name__)
        groups.setdefault(module, []).append(name)
    lines = [
        "# softplan_jax API reference",
        "",
        "<!-- Generated by `python docs/build_api.py` from the docstrings: do not edit by hand. -->",
        "",
        f"Every public name of `softplan_jax` ({len(names)}), grouped by the module that defines it. "
        "Import them from the package: `import softplan_jax as sp; sp.plan(...)`.",
        "",
    ]
    groups = dict(sorted(groups.items(), key=lambda kv: _module_rank(kv[0], pkg.__name__)))
    for module in groups:
        lines.append(f"- [`{module}`](#{module.replace('.', '')}): " + ", ".join(f"`{n}`" for n in groups[module]))
    lines.append("")
    for module, members in groups.items():
        lines += [f"## {module}", ""]
        mod = sys.modules.get(module)
        summary = own_doc(mod) if mod is not None and module != pkg.__name__ else None
        if summary:
            lines += [summary.split("\n\n")[0].replace("\n", " "), ""]
        for name in members:
            lines += _entry(name, getattr(pkg, name))
    return "\n".join(lines).rstrip() + "\n"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--check", action="store_true", help="do not write; exit 1 if docs/api.md is out of date")
    ap.add_argument("--out", default=API_MD, help="output file (default docs/api.md)")
    args = ap.parse_args(argv)
    pkg = _package()
    missing = missing_docstrings(pkg)
    if missing:
        print(f"build_api: public names without a docstring: {', '.join(missing)}", file=sys.stderr)
        return 1
    text = render(pkg)
    if args.check:
        try:
            with open(args.out, encoding="utf-8") as fh:
                current = fh.read()
        except FileNotFoundError:
            current = None
        if current != text:
            print(f"build_api: {args.out} is out of date: run `python docs/build_api.py`", file=sys.stderr)
            return 1
        print(f"build_api: {args.out} is up to date")
        return 0
    with open(args.out, "w", encoding="utf-8") as fh:
        fh.write(text)
    print(f"build_api: wrote {args.out} ({len(public_names(pkg))} public names)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
