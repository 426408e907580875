"""The package's structure: no import cycle anywhere, inside folders too (the layer contract in
pyproject.toml sees only the layers between them)."""

from __future__ import annotations


def test_no_module_imports_one_that_imports_it_back() -> None:
    import grimp

    graph = grimp.build_graph("coopdyn")
    cycles = sorted(
        {
            tuple(sorted((module, imported)))
            for module in graph.modules
            for imported in graph.find_modules_directly_imported_by(module)
            if graph.chain_exists(importer=imported, imported=module)
        }
    )
    assert cycles == []
