"""The package's own imports form no loop (imports under ``TYPE_CHECKING`` aside).

The layer contracts in pyproject.toml (``lint-imports``, run by the test command) forbid
loops between layers; this test also covers the modules that share a layer or a package
(two modules of ``softbody.mesh``, say), where a loop breaks no contract.
"""

from __future__ import annotations

import re

import grimp

#: What a module may import from the package root by name: the compiled core (invisible
#: to the static scan, so read as an import of ``softbody/__init__.py``) and the version.
ROOT_NAMES = {"_core", "__version__"}


def scanned_graph() -> grimp.ImportGraph:
    """The imports among softbody's modules, as the static scan reads them."""
    return grimp.build_graph("softbody", cache_dir=None, exclude_type_checking_imports=True)


def drop_root_names(graph: grimp.ImportGraph) -> grimp.ImportGraph:
    """``graph`` without the imports of the root package that only fetch ``ROOT_NAMES``
    or submodules (``from softbody import _core``); ``import softbody`` or ``from softbody
    import Simulator`` stay."""
    for importer in sorted(graph.find_modules_that_directly_import("softbody")):
        names = set()
        for detail in graph.get_import_details(importer=importer, imported="softbody"):
            match = re.fullmatch(r"from softbody import \(?([\w\s,]+?)\)?", detail["line_contents"])
            if match is None:  # `import softbody`: the whole root
                names.add("softbody")
            else:
                names.update(n.split(" as ")[0].strip() for n in match[1].split(","))
        if all(n in ROOT_NAMES or f"softbody.{n}" in graph.modules for n in names):
            graph.remove_import(importer=importer, imported="softbody")
    return graph


def import_loops(graph: grimp.ImportGraph) -> list[str]:
    """Each import ``a -> b`` (at the top of a module or in a function) for which ``b``
    leads back to ``a``, written as the loop ``a -> b -> ... -> a``."""
    loops = []
    for module in sorted(graph.modules):
        for imported in sorted(graph.find_modules_directly_imported_by(module)):
            chain = graph.find_shortest_chain(importer=imported, imported=module)
            if chain:
                loops.append(" -> ".join((module, *chain)))
    return loops


def test_no_import_loops():
    """Reference: issue 28 ("no import loops other than TYPE_CHECKING ones"). A loop such
    as stability -> solvers -> stability (the solvers' step rule read the stability
    module, which asked the solvers for that rule) works or fails by import order."""
    graph = drop_root_names(scanned_graph())
    assert "softbody.render.frame" in graph.modules, "a package without __init__.py"
    loops = import_loops(graph)
    assert not loops, "import loops:\n" + "\n".join(loops)


def test_loops_are_found():
    """Reference: the check itself, on the real graph with one import added. The
    amplification module importing the solvers (which import it) is a loop; so is an
    engine module taking a public name from the root package (``from softbody import
    Simulator`` in ``softbody.gas``, which the root imports), while ``from softbody
    import _core`` is dropped as no import of the root."""
    graph = drop_root_names(scanned_graph())
    assert not graph.direct_import_exists(importer="softbody.solvers.explicit", imported="softbody")
    graph.add_import(importer="softbody.amplification", imported="softbody.solvers")
    assert any(
        loop.startswith("softbody.amplification -> softbody.solvers")
        for loop in import_loops(graph)
    )
    graph = scanned_graph()
    graph.add_import(
        importer="softbody.gas",
        imported="softbody",
        line_number=1,
        line_contents="from softbody import Simulator",
    )
    loops = import_loops(drop_root_names(graph))
    assert any(loop.startswith("softbody.gas -> softbody ->") for loop in loops)
