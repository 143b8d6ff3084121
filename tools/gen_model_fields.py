"""Generate the Python declaration of the model's core fields from ``core/fields.hpp``.

    python tools/gen_model_fields.py core/fields.hpp OUT.py

The build runs this (CMakeLists.txt installs the result as ``softbody/sim/_model_fields.py``;
``tools/build_core.py`` puts it beside the sources), so that the fields the compiled core
reads are declared once, in the C++ table: ``softbody.Model`` derives from the generated
``CoreFields`` dataclass, whose fields carry the table's description, unit and shape as
their docstrings. Plain Python with no imports beyond the standard library: it runs before
the package exists.
"""

from __future__ import annotations

import re
import sys
import textwrap
from pathlib import Path

TYPES = {"f64": "np.ndarray", "i64": "np.ndarray", "vec3": "np.ndarray",
         "f64_value": "float", "i64_value": "int"}  # fmt: skip


def _split(arguments: str) -> list[str]:
    """Top-level comma-separated arguments (parentheses and string literals respected)."""
    out, depth, quoted, start = [], 0, False, 0
    for k, ch in enumerate(arguments):
        if ch == '"' and (k == 0 or arguments[k - 1] != "\\"):
            quoted = not quoted
        elif not quoted and ch in "([":
            depth += 1
        elif not quoted and ch in ")]":
            depth -= 1
        elif not quoted and ch == "," and depth == 0:
            out.append(arguments[start:k].strip())
            start = k + 1
    out.append(arguments[start:].strip())
    return out


def _calls(body: str, name: str) -> list[list[str]]:
    """The argument lists of every ``name(...)`` in ``body``."""
    calls, at = [], 0
    while (k := body.find(name + "(", at)) >= 0:
        depth, quoted, j = 0, False, k + len(name)
        for j in range(k + len(name), len(body)):
            if body[j] == '"' and body[j - 1] != "\\":
                quoted = not quoted
            elif not quoted:
                depth += {"(": 1, ")": -1}.get(body[j], 0)
                if depth == 0:
                    break
        calls.append(_split(body[k + len(name) + 1 : j]))
        at = j + 1
    return calls


def _string(literals: str) -> str:
    """Adjacent C string literals as one Python string."""
    return "".join(re.findall(r'"((?:[^"\\]|\\.)*)"', literals))


def parse(text: str) -> list[dict]:
    """Every field of the table, parts in SOFTBODY_MODEL_PARTS's order."""
    text = re.sub(r"//[^\n]*", "", text).replace("\\\n", " ")
    macros = dict(re.findall(r"#define\s+(\w+)\(\w+\)\s*([^\n]*)", text))
    fields = []
    for part in _calls(macros["SOFTBODY_MODEL_PARTS"], "P"):
        for f in _calls(macros[part[2]], "F"):
            fields.append({
                "part": f[0], "member": f[1], "name": f[2], "type": f[3],
                "shape": f[4].replace(" ", ""), "check": f[5],
                "unit": _string(f[6]), "doc": _string(f[7]),
            })  # fmt: skip
    return fields


def docstring(field: dict) -> str:
    """The description's first clause, its unit and shape, then the rest (after ';')."""
    head, _, rest = field["doc"].partition("; ")
    doc = head[0].upper() + head[1:]
    if field["unit"]:
        doc += f" [{field['unit']}]"
    if field["type"] in ("f64", "i64", "vec3"):
        shape = field["shape"].replace(",", ", ")
        doc += f", shape {shape[:-1]},)" if "," not in shape else f", shape {shape}"
    return doc + (f"; {rest}" if rest else "") + "."


def generate(text: str) -> str:
    lines = [
        '"""The model fields the compiled core reads: generated from ``core/fields.hpp`` by',
        '``tools/gen_model_fields.py`` at build time (do not edit)."""',
        "",
        "from __future__ import annotations",
        "",
        "from dataclasses import dataclass",
        "",
        "import numpy as np",
        "",
        "",
        "@dataclass(frozen=True, eq=False)",
        "class CoreFields:",
        '    """The fields of :class:`softbody.Model` the compiled core reads, as declared in',
        '    ``core/fields.hpp`` (SI units; N particles, S springs, A attachments, T triangles,',
        '    B bodies, M Monte Carlo samples, K gas schedule points, P pins, C colliders)."""',
        "",
    ]
    fields = parse(text)
    for f in fields:
        lines.append(f"    {f['name']}: {TYPES[f['type']]}")
        text = textwrap.fill(f'"""{docstring(f)}"""', width=96, initial_indent="    ",
                             subsequent_indent="    ", break_on_hyphens=False)  # fmt: skip
        lines.append(text)
    lines += ["", "", "#: (name, type, shape, check, unit) of every field, in the table's order",
              "FIELDS = ("]  # fmt: skip
    for f in fields:
        lines.append(f"    ({f['name']!r}, {f['type']!r}, {f['shape']!r}, {f['check']!r}, "
                     f"{f['unit']!r}),")  # fmt: skip
    lines.append(")")
    return "\n".join(lines) + "\n"


def main() -> None:
    source, out = Path(sys.argv[1]), Path(sys.argv[2])
    text = generate(source.read_text())
    tmp = out.with_name(out.name + ".tmp")
    tmp.write_text(text)
    tmp.replace(out)


if __name__ == "__main__":
    main()
