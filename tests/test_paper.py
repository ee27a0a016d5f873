"""The write-up (``paper/``): no result number is typed in its sources, and it builds from generated files.

What counts as a *result number* in a ``.tex`` source outside ``paper/generated/`` (checked in the document
body, after ``\\begin{document}``, with comments removed and the arguments of ``\\label``, ``\\ref``,
``\\cite``, ``\\input``, ``\\includegraphics``, ``\\res``, ``\\paperres``, ``\\val``, ``\\best``,
``\\bestacc`` and every optional ``[...]`` argument removed):

1. any number with a decimal point (``53.55``, ``0.88``), unless a TeX length unit follows it
   (``0.9\\linewidth``, ``0.35em``: layout, not a result);
2. any number followed (after optional spaces, ``\\,`` or ``~``) by a percent sign (``\\%``, ``\\pct``,
   ``percent``), by ``points`` / ``pp``, or by a speed or time unit (``FPS``, ``fps``, ``frames``,
   ``inst/s``, ``instances per second``, ``ms``, ``seconds``, ``minutes``, ``hours``).

Allowed: the values of the paper's *method* that the text quotes, listed in :data:`ALLOWED` (the ADD(-S)
threshold of 10 % of the diameter). Integers without such a unit (years, section, table and equation
numbers, the paper's 18 objects) are not result numbers. Numbers of ours and of the paper go through the
generated macros (``\\res{name}{field}``, ``\\paperres{table}{method}``, ``\\val{name}``).
"""

from __future__ import annotations

import re
import shutil
import subprocess
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
PAPER = REPO / "paper"

#: Specification values the prose may quote (normalised: spacing commands removed).
ALLOWED = ("10\\pct",)

_DIM = r"(?:pt|em|ex|mm|cm|in|bp|\\linewidth|\\textwidth|\\columnwidth)"
_UNIT = (r"(?:\\%|\\pct|percent|points\b|pp\b|FPS|fps|frames|inst/s|instances per second|ms\b|seconds|minutes|hours)")
_NUM = r"(?<![\w.])\d+(?:[.,]\d+)*"
_ARGS = re.compile(r"\\(?:label|ref|eqref|cite|input|include|includegraphics|res|paperres|val|best|bestacc|method"
                   r"|begin|end|usepackage|documentclass)\*?(?:\[[^\]]*\])*(?:\{[^{}]*\})+")
_OPT = re.compile(r"\[[^\]]*\]")


def result_numbers(tex: str) -> list[str]:
    """The result numbers of a ``.tex`` source (see the module docstring), as they appear after
    normalisation; empty when there are none."""
    body = tex.split("\\begin{document}", 1)[1] if "\\begin{document}" in tex else tex
    body = re.sub(r"(?<!\\)%.*", "", body)  # comments
    body = _ARGS.sub(" ", body)
    body = _OPT.sub(" ", body)
    body = re.sub(r"\\,|~|\\ |\{\}", " ", body)
    body = re.sub(r"[ \t]+", " ", body)
    for a in ALLOWED:
        body = body.replace(a, " ").replace(a.replace("\\pct", " \\pct"), " ")
    found = []
    for m in re.finditer(_NUM, body):
        num, rest = m.group(0), body[m.end():m.end() + 40]
        if re.match(r"\s*" + _DIM, rest):
            continue
        if re.fullmatch(r"\d+\.\d+", num) or re.match(r"\s*" + _UNIT, rest):
            found.append((num + rest[:12]).strip())
    return found


def test_the_checker_finds_result_numbers():
    doc = "\\begin{document}\n"
    assert [n.split()[0] for n in result_numbers(doc + "Super4PCS reaches 57.32 on the subset.")] == ["57.32"]
    assert result_numbers(doc + "it reaches 53\\,\\% here") and result_numbers(doc + "at 14 FPS on")
    assert result_numbers(doc + "it gains 4 points over") and result_numbers(doc + "70~\\% of")
    assert result_numbers(doc + "took 48 minutes") and result_numbers(doc + "a 3.1 speed-up")
    ok = (doc + "Section~\\ref{sec:x}, eq.~4, 18 objects, the year 2023, \\res{single_pred_super4pcs}{acc}\\pct{} "
          "and \\paperres{III}{super4pcs}\\,\\% with \\includegraphics[width=0.9\\linewidth]{fig7.png} "
          "below 10\\pct{} of the diameter; \\vspace{0.5em} % a comment with 12.5 %\n")
    assert result_numbers(ok) == []
    assert result_numbers("\\usepackage[margin=2.2cm]{geometry}\n12.5 in the preamble\n" + doc) == []


def _sources() -> list[Path]:
    return sorted(p for p in PAPER.rglob("*.tex") if "generated" not in p.relative_to(PAPER).parts
                  and "build" not in p.relative_to(PAPER).parts)


def test_no_result_number_is_typed_in_the_write_up():
    srcs = _sources()
    assert PAPER / "paper.tex" in srcs
    bad = {str(p.relative_to(REPO)): result_numbers(p.read_text(encoding="utf-8")) for p in srcs}
    bad = {k: v for k, v in bad.items() if v}
    assert not bad, f"result numbers typed in the write-up (use the generated macros \\res, \\paperres, \\val): {bad}"


def test_every_generated_input_is_written_by_notebook_07():
    tex = (PAPER / "paper.tex").read_text()
    inputs = set(re.findall(r"\\input\{([^}]+)\}", tex))
    graphics = set(re.findall(r"\\includegraphics(?:\[[^\]]*\])?\{([^}]+)\}", tex))
    mk = (REPO / "mk" / "reproduce.mk").read_text()
    nb = (REPO / "notebooks" / "07_evaluation.py").read_text() + (
        REPO / "notebooks" / "02_dataset_overview.py"
    ).read_text()
    for name in inputs:
        assert f"{name}.tex" in mk or re.search(rf"\b{re.escape(name)}\b", mk) or "per_object_" in name, name
    for g in graphics:
        assert g in nb, f"{g}: no notebook writes it"


@pytest.mark.slow
@pytest.mark.skipif(shutil.which("latexmk") is None or shutil.which("pdflatex") is None, reason="LaTeX not installed")
@pytest.mark.parametrize("lmo", [False, True])
def test_the_write_up_builds_from_generated_files(tmp_path, lmo):
    """paper.tex compiles against macros and tables generated from a few result files (without and with
    LM-O rows: the two branches of its Table I text)."""
    import matplotlib

    matplotlib.use("Agg")
    from sixdpose.artifacts.results import write_result
    from sixdpose.reporting import report

    res = tmp_path / "results"
    names = ("single_pred_super4pcs", "test_gt_ransac_icp", "test_gt_learned_it2")
    for i, name in enumerate(names + (("lmo_gt_ransac_icp", "lmo_gt_super4pcs") if lmo else ())):
        write_result(
            name,
            {"accuracy": 40.0 + i, "n_gt": 10, "n_correct": 4, "fps": 1.5, "instances_per_s": 6.0, "n_images": 3},
            rows=[{"obj_id": 1, "name": "055_baseball", "n_gt": 10, "add_s_accuracy": 40.0}],
            results_dir=res,
        )
    e = report.load_entries(res)
    gen, fig = tmp_path / "gen", tmp_path / "fig"
    gen.mkdir()
    fig.mkdir()
    report.write_table1(e, fig / "t1.csv", gen / "table1.tex")
    report.write_table2(e, fig / "t2.csv", gen / "table2.tex")
    report.write_table3(e, fig / "t3.csv", gen / "table3.tex")
    for s in ("test", "single"):
        for k in ("gt", "pred"):
            report.write_per_object(e, s, k, fig / "p.csv", gen / f"per_object_{s}_{k}.tex")
    report.write_real_table(res, fig / "real.csv", gen / "table_real.tex")  # no results: the "not run" row
    report.write_ablation_table(res, "smoke", fig / "abl.csv", gen / "table_ablation.tex")
    report.write_ablation_table(res, "smoke", fig / "abls.csv", gen / "table_ablation_seeds.tex",
                                name="pose_ablation_seeds")  # not run: the "not run" row
    report.write_table2_e2e(res, fig / "t2e.csv", gen / "table2_e2e.tex")  # no benchmark: the "not run" row
    from sixdpose.reporting.claims import write_claims

    write_claims(res, "smoke", fig / "claims.csv", gen / "claims.tex")
    report.write_macros(e, "smoke", gen / "macros.tex",
                        extra={**report.dataset_values(e, tmp_path), **report.beyond_findings(res, "smoke")})
    (fig / "stats.csv").write_text("quantity,paper,this dataset\nimages,\"25,000\",6\n")
    report.dataset_table(fig / "stats.csv", gen / "table_dataset.tex")
    for png in ("fig2_lmo_vs_ours.png", "fig3_random_images.png", "fig7.png", "accuracy_threshold.png"):
        report.placeholder_figure(png).savefig(fig / png)
    out = tmp_path / "build"
    env = {"TEXINPUTS": f"{gen}//:{fig}//:", "PATH": "/usr/bin:/bin"}
    p = subprocess.run(["latexmk", "-pdf", "-interaction=nonstopmode", "-halt-on-error", f"-outdir={out}", "paper.tex"],
                       cwd=PAPER, env=env, capture_output=True, text=True, timeout=300)
    assert p.returncode == 0, p.stdout[-3000:]
    log = (out / "paper.log").read_text(errors="replace")
    assert (out / "paper.pdf").stat().st_size > 10000
    if shutil.which("pdftotext"):
        text = subprocess.run(["pdftotext", str(out / "paper.pdf"), "-"], capture_output=True, text=True).stdout
        assert "Pipeline check, not results" in text  # the smoke profile's banner
        assert ("LM-O rows of ours were not run" in text) is not lmo
    assert "Undefined control sequence" not in log and "undefined references" not in log
    # missing results warn
    assert ("no result lmo_gt_ransac_icp" in log) is False and ("sixdpose Warning: no result" in log) is True


def test_every_figure_of_the_write_up_is_listed_and_placeholders_say_what_makes_it(tmp_path):
    """sixdpose.reporting.writeup.FIGURES are the write-up's figures; those missing from figures/<profile>/
    get a placeholder naming the command that makes them (the PDF rule of mk/reproduce.mk)."""
    from sixdpose.reporting import writeup

    tex = (PAPER / "paper.tex").read_text()
    graphics = set(re.findall(r"\\includegraphics(?:\[[^\]]*\])?\{([^}]+)\}", tex))
    assert {f.name for f in writeup.FIGURES} == graphics
    figs = tmp_path / "fig"
    figs.mkdir()
    (figs / "accuracy_threshold.png").write_bytes(b"png")
    out = tmp_path / "missing"
    (out).mkdir()
    (out / "accuracy_threshold.png").write_bytes(b"stale placeholder")
    lines = writeup.write_placeholders(figs, out, "cpu")
    assert sorted(p.name for p in out.iterdir()) == sorted(graphics - {"accuracy_threshold.png"})
    assert len(lines) == 3 and any("make reproduce PROFILE=cpu" in line for line in lines)
    assert any("make fig2 PROFILE=cpu RECOMPUTE=yes" in line for line in lines)


def test_the_committed_cpu_figures_of_the_write_up():
    """figures/cpu holds the write-up's figures built from the committed results; the ones drawn from a
    dataset (not committed) are exactly those the write-up shows as placeholders."""
    from sixdpose.reporting import writeup

    missing = {f.name for f in writeup.missing(REPO / "figures" / "cpu")}
    assert missing <= {"fig2_lmo_vs_ours.png", "fig3_random_images.png", "fig7.png"}
    assert (REPO / "figures" / "cpu" / "accuracy_threshold.png").is_file()
    size = sum(p.stat().st_size for p in (REPO / "figures" / "cpu").glob("*.png"))
    assert size < 5 * 2**20, f"figures/cpu/*.png together {size / 2**20:.1f} MB (keep them under 5 MB)"
