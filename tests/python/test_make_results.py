"""scripts/make_results.py: a resumed set's finished part is shipped under results/<name>/progress/
and a work folder that has not started continues from it, without overwriting one that has."""
import importlib.util
from pathlib import Path

SCRIPT = Path(__file__).resolve().parents[2] / "scripts" / "make_results.py"


def load(root):
    spec = importlib.util.spec_from_file_location("make_results", SCRIPT)
    m = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(m)
    m.ROOT = str(root)
    return m


def test_progress_is_shipped_and_continued(tmp_path):
    m = load(tmp_path / "repo")
    work = tmp_path / "work" / "flow_campaign"
    (work / "level3" / "parts").mkdir(parents=True)
    (work / "level3" / "campaign.json").write_text('{"seed": 20261129}')
    (work / "level3" / "parts" / "rank0.csv").write_text("case_id\n0\n")
    (work / "level3" / "checkpoint").mkdir()  # not part of the progress
    m.save_progress("flow_campaign", str(work))
    shipped = tmp_path / "repo" / "results" / "flow_campaign" / "progress" / "level3"
    assert (shipped / "campaign.json").read_text() == '{"seed": 20261129}'
    assert (shipped / "parts" / "rank0.csv").read_text() == "case_id\n0\n"
    assert not (shipped / "checkpoint").exists()
    assert not (shipped.parent / "level2").exists()  # nothing of level 2 was there

    fresh = tmp_path / "other" / "flow_campaign"
    fresh.mkdir(parents=True)
    m.restore_progress("flow_campaign", str(fresh))
    assert (fresh / "level3" / "parts" / "rank0.csv").read_text() == "case_id\n0\n"
    assert (fresh / "level3" / "campaign.json").exists()

    # A work folder that has started keeps its own files.
    (work / "level3" / "parts" / "rank0.csv").write_text("case_id\n0\n1\n")
    m.restore_progress("flow_campaign", str(work))
    assert (work / "level3" / "parts" / "rank0.csv").read_text() == "case_id\n0\n1\n"
