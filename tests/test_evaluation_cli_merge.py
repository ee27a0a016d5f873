"""``sixdpose merge-results`` and :func:`sixdpose.artifacts.poses.merge_by_score`: pose-source fusion by score."""

from __future__ import annotations

import numpy as np
import pytest

from sixdpose.artifacts.poses import PoseEstimate, ResultsError, merge_by_score, read_results, write_results
from sixdpose.cli import main


def _row(scene, im, obj, score, angle, time):
    c, s = np.cos(angle), np.sin(angle)
    R = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]])
    return PoseEstimate(scene, im, obj, score, R, np.array([0, 0, 0.5]), time)


def test_merge_keeps_the_best_scored_row_and_sums_the_times(tmp_path):
    a = [_row(0, 1, 5, 0.9, 0.0, 2.0), _row(0, 1, 5, 0.2, 0.0, 2.0), _row(0, 2, 6, 0.0, 0.0, 1.0)]
    b = [_row(0, 1, 5, 0.5, 1.0, 3.0), _row(0, 1, 5, 0.6, 1.0, 3.0), _row(0, 2, 6, 0.4, 1.0, 0.5)]
    rows, chosen = merge_by_score([a, b])
    assert [r.score for r in rows] == [0.9, 0.6, 0.4] and chosen == [1, 2]
    assert rows[1].R[1, 0] == pytest.approx(np.sin(1.0))  # the second table's pose came with its score
    assert [r.time for r in rows] == [5.0, 5.0, 1.5]  # both sources ran on every image
    tie, _ = merge_by_score([[_row(0, 1, 5, 0.5, 0.0, 1.0)], [_row(0, 1, 5, 0.5, 1.0, 1.0)]])
    assert tie[0].R[0, 0] == pytest.approx(1.0)  # a tie keeps the earlier table's row
    # the CLI writes the merged CSV and says where the rows came from
    pa, pb, out = tmp_path / "a.csv", tmp_path / "b.csv", tmp_path / "m.csv"
    write_results(a, pa)
    write_results(b, pb)
    assert main(["merge-results", "--results", str(pa), "--results", str(pb), "--out", str(out)]) == 0
    assert [r.score for r in read_results(out)] == pytest.approx([0.9, 0.6, 0.4])


def test_merge_refuses_tables_of_other_instances(tmp_path, capsys):
    a = [_row(0, 1, 5, 0.9, 0.0, 1.0), _row(0, 1, 6, 0.9, 0.0, 1.0)]
    with pytest.raises(ResultsError, match=r"row 2 is .*\(0, 1, 7\)"):
        merge_by_score([a, [_row(0, 1, 5, 0.9, 0.0, 1.0), _row(0, 1, 7, 0.9, 0.0, 1.0)]])
    with pytest.raises(ResultsError, match="1 rows"):
        merge_by_score([a, a[:1]])
    with pytest.raises(ResultsError, match="at least two"):
        merge_by_score([a])
    pa, out = tmp_path / "a.csv", tmp_path / "m.csv"
    write_results(a, pa)
    assert main(["merge-results", "--results", str(pa), "--out", str(out)]) == 2  # one table: one line
    assert "two or more" in capsys.readouterr().err
    assert main(["merge-results", "--results", str(pa), "--results", str(tmp_path / "no.csv"), "--out", str(out)]) == 2
    assert "no.csv" in capsys.readouterr().err and not out.exists()


def test_merge_warns_when_the_scores_are_not_the_same_verifications(tmp_path, capsys):
    """The sources' ``.config.yml``: a source made without ``--verify``, or verified with other
    ``verify_*`` settings, is named in a warning line (its scores mean something else); the merge runs."""
    a = [_row(0, 1, 5, 0.9, 0.0, 1.0)]
    paths = [tmp_path / f"{n}.csv" for n in ("reg", "net", "wide", "plain")]
    for p in paths:
        write_results(a, p)
    (tmp_path / "reg.config.yml").write_text("verify: true\nverify_tau_rel: 0.03\nseed: 0\n")  # register's layout
    (tmp_path / "net.config.yml").write_text("verify: true\nverify_config:\n  verify_tau_rel: 0.03\n")  # predict-pose's
    (tmp_path / "wide.config.yml").write_text("verify: true\nverify_config:\n  verify_tau_rel: 0.05\n")
    (tmp_path / "plain.config.yml").write_text("verify: false\nicp: true\n")
    out = tmp_path / "m.csv"
    assert main(["merge-results", "--results", str(paths[0]), "--results", str(paths[1]), "--out", str(out)]) == 0
    assert "warning" not in capsys.readouterr().err  # the same verification: no warning
    for other, text in ((paths[2], "verify_tau_rel=0.05"), (paths[3], "not made with the hypothesis verification")):
        assert main(["merge-results", "--results", str(paths[0]), "--results", str(other), "--out", str(out)]) == 0
        err = capsys.readouterr().err
        assert text in err and str(other) in err and out.is_file()
