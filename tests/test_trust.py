"""Files are data: a sweep table, a result or a scene file someone sends runs no code it names,
and is refused by name when it is damaged or hostile (docs/trust.md)."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import pytest

import coopdyn as cd
from coopdyn.__main__ import main
from coopdyn.sweeps import rerun

EVIL = """
from pathlib import Path
Path({marker!r}).write_text("ran")
def make_case(**kwargs):
    Path({marker!r}).write_text("ran")
"""


def book_case(stiffness: float = 1.0) -> cd.Scene:
    return cd.scenes.linear_book()


def forged_table(tmp_path: Path, source: dict[str, object]) -> Path:
    """A real sweep's table whose recorded make_case is replaced by ``source``."""
    import pyarrow.parquet as pq

    cd.sweep(book_case, {"stiffness": [1.0]}, duration=0.01, executor="serial", out=tmp_path / "sweep", progress=False)
    path = tmp_path / "sweep" / "table.parquet"
    arrow = pq.read_table(path)
    metadata = dict(arrow.schema.metadata)
    meta = json.loads(metadata[b"coopdyn.sweep"])
    meta["source"] = {"kind": "python", **source}
    metadata[b"coopdyn.sweep"] = json.dumps(meta).encode()
    pq.write_table(arrow.replace_schema_metadata(metadata), path)
    return path


@pytest.mark.parametrize("by", ["file", "module"])
def test_a_hostile_table_runs_nothing_it_names(tmp_path: Path, monkeypatch: pytest.MonkeyPatch, by: str) -> None:
    marker = tmp_path / "marker.txt"
    evil = tmp_path / "lib" / "evil_payload.py"
    evil.parent.mkdir()
    evil.write_text(EVIL.format(marker=str(marker)))
    monkeypatch.syspath_prepend(str(evil.parent))
    module = "evil_payload" if by == "module" else "__main__"
    table = forged_table(tmp_path, {"module": module, "qualname": "make_case", "file": str(evil), "name": "make_case"})
    with pytest.raises(cd.SweepError, match=r"does not import or run code it names.*--case .*evil_payload.*--trust"):
        rerun(table, 0)
    assert main(["sweep", "--rerun", str(table), "0"]) == 2
    assert not marker.exists() and "evil_payload" not in sys.modules
    # named by the user, or trusted explicitly, it runs (and here it is not a case maker at all)
    assert rerun(table, 0, trust=True).differences
    assert marker.read_text() == "ran"


def test_a_rerun_takes_the_code_the_user_names(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    table = forged_table(tmp_path, {"module": None, "qualname": None, "file": None, "name": "<lambda>"})
    here = Path(__file__).resolve()
    assert rerun(table, 0, make_case=book_case).identical
    assert rerun(table, 0, make_case=f"{here}:book_case").identical
    assert main(["sweep", "--rerun", str(table), "0", "--case", f"{here}:book_case"]) == 0
    with pytest.raises(cd.SweepError, match="MODULE:FUNCTION or FILE.py:FUNCTION"):
        rerun(table, 0, make_case="book_case")
    with pytest.raises(cd.SweepError, match="no file"):
        rerun(table, 0, make_case=f"{tmp_path}/missing.py:f")
    with pytest.raises(cd.SweepError, match="defines no nothing_here"):
        rerun(table, 0, make_case=f"{here}:nothing_here")
    assert main(["sweep", "x.toml", "--trust"]) == 2
    assert "--trust goes with --rerun" in capsys.readouterr().err
