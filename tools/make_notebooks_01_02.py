"""Write notebooks 01 and 02 (committed without outputs). Run: .venv/bin/python tools/make_notebooks_01_02.py"""

import nbformat as nbf

PARAMS = '''# Parameters (papermill overrides these; SIXDPOSE_PROFILE=smoke is the CI / small switch)
import os
PROFILE = os.environ.get("SIXDPOSE_PROFILE", "smoke")  # smoke (CI), demo (laptop CPU), paper (25,000 images)
DATA = None  # None: $SIXDPOSE_DATA, else ../data/<PROFILE>
FIGURES = "../figures"
'''
RESOLVE = '''DATA = DATA or os.environ.get("SIXDPOSE_DATA") or f"../data/{PROFILE}"  # after papermill's injected values
'''


def nb(cells):
    n = nbf.v4.new_notebook()
    n.metadata["kernelspec"] = {"name": "python3", "display_name": "Python 3", "language": "python"}
    n.metadata["language_info"] = {"name": "python"}
    out = []
    for kind, src, *tags in cells:
        c = nbf.v4.new_markdown_cell(src) if kind == "md" else nbf.v4.new_code_cell(src)
        if tags:
            c.metadata["tags"] = tags
        out.append(c)
    n.cells = out
    return n


nb01 = nb([
    ("md", "# 01 · Generate the synthetic dataset (paper section III)\n\n"
           "Drake drops 5-20 target and 5-10 noise YCB objects on a table (some beyond its edge), simulates "
           "the physics until everything rests, and renders 20 RGB-D views along a random camera arc. "
           "The output follows the paper's layout (section III-C); see `sixdpose.datasets.synthetic`."),
    ("code", PARAMS + "SCENES = None  # None: the profile's number of scenes\nVIEWS = None\nSEED = 0\nWORKERS = 2\n", "parameters"),
    ("code", RESOLVE + "from pathlib import Path\n\nimport matplotlib\nmatplotlib.use(\"Agg\")\nimport matplotlib.pyplot as plt\n\n"
             "from sixdpose.datasets import open_dataset\nfrom sixdpose.datasets.viz import plot_views\n"
             "from sixdpose.generation import generate, profile\n\nPath(FIGURES).mkdir(parents=True, exist_ok=True)"),
    ("md", "Generate (or finish an interrupted run: completed scenes are kept)."),
    ("code", "cfg = profile(PROFILE, scenes=SCENES, views=VIEWS, seed=SEED)\n"
             "summary = generate(DATA, cfg, workers=WORKERS)\n"
             "print({k: v for k, v in summary.items() if k != \"manifest\"})\n"
             "assert not summary[\"scenes_failed\"], summary[\"scenes_failed\"]"),
    ("md", "One scene's views with the target instance masks (noise objects carry no annotation)."),
    ("code", "ds = open_dataset(DATA)\nscene = ds.keys()[0][0]\n"
             "ids = [i for s, i in ds.keys() if s == scene][:6]\n"
             "fig = plot_views([ds.load(i) for i in ids], ncols=3, title=f\"scene {scene}\")\n"
             "fig.savefig(f\"{FIGURES}/scene_views.png\", dpi=100)\nplt.show()"),
])

nb02 = nb([
    ("md", "# 02 · Dataset overview\n\nThe paper's Fig. 3 (nine random images), the ground truth drawn over the "
           "images, and the dataset's statistics against the claims of section III."),
    ("code", PARAMS + "SEED = 0\n", "parameters"),
    ("code", RESOLVE + "import csv\nfrom pathlib import Path\n\nimport matplotlib\nmatplotlib.use(\"Agg\")\nimport matplotlib.pyplot as plt\nimport numpy as np\n\n"
             "from sixdpose.datasets import open_dataset\nfrom sixdpose.datasets.stats import claims_table, dataset_statistics, plot_statistics\n"
             "from sixdpose.datasets.viz import plot_gt_projection, plot_views\nfrom sixdpose.generation import ensure_dataset\n\n"
             "ensure_dataset(DATA, profile=PROFILE)\nds = open_dataset(DATA)\nPath(FIGURES).mkdir(parents=True, exist_ok=True)\nrng = np.random.default_rng(SEED)"),
    ("md", "## Fig. 3: nine random images"),
    ("code", "ids = rng.choice(ds.image_ids, size=min(9, len(ds)), replace=False)\n"
             "fig = plot_views([ds.load(int(i), with_masks=False) for i in ids], ncols=3, masks=False)\n"
             "fig.savefig(f\"{FIGURES}/fig3_random_images.png\", dpi=100)\nplt.show()"),
    ("md", "## Ground truth: model points projected at the GT pose\n\nEvery annotated instance's reference "
           "model (`models/<object>.ply`) drawn at its `gt.yml` pose with the image's `cam_K`."),
    ("code", "ids = rng.choice(ds.image_ids, size=min(4, len(ds)), replace=False)\n"
             "samples = [ds.load(int(i), with_masks=False) for i in ids]\n"
             "models = {oid: ds.model(oid).points for oid in {o.obj_id for s in samples for o in s.instances}}\n"
             "fig = plot_gt_projection(samples, models)\nfig.savefig(f\"{FIGURES}/gt_projection.png\", dpi=100)\nplt.show()"),
    ("md", "## Statistics against the paper's claims"),
    ("code", "st = dataset_statistics(ds)\nrows = claims_table(st)\n"
             "with open(f\"{FIGURES}/dataset_statistics.csv\", \"w\", newline=\"\") as f:\n"
             "    csv.writer(f).writerows([(\"quantity\", \"paper\", \"this dataset\"), *rows])\n"
             "for q, paper, ours in rows:\n    print(f\"{q:45s} {paper:30s} {ours}\")\n"
             "fig = plot_statistics(st)\nfig.savefig(f\"{FIGURES}/dataset_statistics.png\", dpi=100)\nplt.show()"),
    ("code", "# sanity checks of the dataset against section III (they hold at every scale)\n"
             "assert st[\"targets_per_scene\"].min() >= 5 and st[\"targets_per_scene\"].max() <= 20 or PROFILE == \"smoke\"\n"
             "assert st[\"max_instances_of_one_object\"] <= 4\n"
             "assert len(st[\"instances_per_object\"]) <= 18"),
])

nbf.write(nb01, "notebooks/01_generate_dataset.ipynb")
nbf.write(nb02, "notebooks/02_dataset_overview.ipynb")
