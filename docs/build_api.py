"""Build the API reference ``docs/api.md`` from the docstrings of softplan_jax's public names.

::

    python docs/build_api.py            # (re)write docs/api.md
    python docs/build_api.py --check    # exit 1 if docs/api.md is not up to date

The public names are ``softplan_jax.__all__`` (the top level), then the
``__all__`` of each sub-namespace (``softplan_jax.geometry``, ...), one section
each, in the order of the layers.

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

# The sub-namespaces, one per layer of the package, top-down after the top level (DESIGN.md).
NAMESPACES = ["moving", "geometry", "scenarios", "clouds", "planning", "search", "tuning", "plotting", "cli"]


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


def _namespaces(pkg):
    """(dotted name, module, its names) for the top level and every sub-namespace."""
    import importlib

    out = [(pkg.__name__, pkg, public_names(pkg))]
    for space in NAMESPACES:
        mod = importlib.import_module(f"{pkg.__name__}.{space}")
        out.append((mod.__name__, mod, public_names(mod)))
    return out


def render(pkg=None) -> str:
    """The text of docs/api.md."""
    pkg = pkg or _package()
    spaces = _namespaces(pkg)
    top = set(spaces[0][2])
    lines = [
        "# softplan_jax API reference",
        "",
        "<!-- Generated by `python docs/build_api.py` from the docstrings: do not edit by hand. -->",
        "",
        f"The top level of `softplan_jax` ({len(spaces[0][2])} names: `import softplan_jax as sp; sp.plan(...)`), "
        "then one sub-namespace per layer of the package (`sp.geometry`, `sp.planning`, ...). A name of the top "
        "level is documented there only.",
        "",
    ]
    for dotted, _, names in spaces:
        lines.append(f"- [`{dotted}`](#{dotted.replace('.', '')}): " + ", ".join(f"`{n}`" for n in names))
    moved = getattr(pkg, "_MOVED", {})
    if moved:
        lines += ["", "Names that were at the top level before the sub-namespaces still work there, with a "
                  "`DeprecationWarning`: " + ", ".join(f"`{n}` (`{pkg.__name__}.{w}`)" for n, w in moved.items())
                  + "."]
    lines.append("")
    for dotted, mod, names in spaces:
        lines += [f"## {dotted}", ""]
        summary = own_doc(mod)
        if summary:
            lines += [summary.split("\n\n")[0].replace("\n", " "), ""]
        own = [n for n in names if dotted == pkg.__name__ or n not in top]
        also = [n for n in names if n not in own]
        if also:
            lines += ["Also here (documented at the top level): " + ", ".join(f"`{n}`" for n in also) + ".", ""]
        for name in own:
            lines += _entry(name, getattr(mod, name))
    return "\n".join(lines).rstrip() + "\n"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--check", action="store_true", help="do not write; exit 1 if docs/api.md is out of date")
    ap.add_argument("--out", default=API_MD, help="output file (default docs/api.md)")
    args = ap.parse_args(argv)
    pkg = _package()
    missing = [f"{dotted}.{n}" if dotted != pkg.__name__ else n for dotted, mod, _ in _namespaces(pkg)
               for n in missing_docstrings(mod)]
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
    count = sum(len(names) for _, _, names in _namespaces(pkg))
    print(f"build_api: wrote {args.out} ({count} entries of {len(NAMESPACES) + 1} namespaces)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
