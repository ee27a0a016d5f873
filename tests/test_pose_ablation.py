"""The pose ablation over seeds (``run_ablation(seeds=..., refiner_variants=...)``, ``pose-ablation --seeds
--refiner-noise``): one row per variant with the mean, spread and per-seed figures; the refiner rows."""

from __future__ import annotations

import statistics

import pytest

from test_reg_helpers import write_synthetic_dataset


@pytest.fixture(scope="module")
def ablation(tmp_path_factory):
    from sixdpose.pose.ablation import REFINER_VARIANTS, run_ablation

    root = tmp_path_factory.mktemp("abl")
    data = write_synthetic_dataset(root / "syn", n_images=2, two_instances_in_first=False)
    variants = {"base": {"translation": "centroid_offset"}, "+ group norm": {"translation": "centroid_offset",
                                                                             "norm": "group"}}
    table = run_ablation(data, data, root / "runs", profile="smoke", variants=variants, seeds=(0, 1),
                         refiner_variants=REFINER_VARIANTS, epochs=1, time_budget=0.0)
    return root / "runs", table


def test_every_variant_is_trained_once_per_seed_and_summarised(ablation):
    runs, table = ablation
    from sixdpose.pose.ablation import REFINER_VARIANTS

    assert list(table["variant"]) == ["base", "+ group norm", *REFINER_VARIANTS]
    assert list(table["network"]) == ["pose", "pose", "refiner", "refiner"]
    assert set(table["seeds"]) == {2}
    names = sorted(p.name for p in runs.iterdir() if p.is_dir())
    assert names == ["0_base", "0_base_s1", "1_group_norm", "1_group_norm_s1", "r0_refiner_trained_with_noise__paper",
                     "r0_refiner_trained_with_noise__paper_s1", "r1_refiner_trained_without_noise",
                     "r1_refiner_trained_without_noise_s1"]
    for row in table.to_dict("records"):
        per_seed = [float(x) for x in row["val_add_per_seed"].split("/")]
        assert len(per_seed) == 2
        assert row["val_add"] == pytest.approx(statistics.fmean(per_seed), abs=0.01)
        assert row["val_add_std"] == pytest.approx(statistics.stdev(per_seed), abs=0.01)
    assert table.loc[1, "norm"] == "group" and table.loc[0, "norm"] == "none"


def test_the_seeds_train_different_networks_and_the_refiners_their_noise(ablation):
    import torch

    from sixdpose.pose.checkpoint import load

    runs, _ = ablation
    a, b = load(runs / "0_base")["model"], load(runs / "0_base_s1")["model"]
    assert any(not torch.equal(a[k], b[k]) for k in a)  # another seed, another initialisation
    cfg = load(runs / "r1_refiner_trained_without_noise_s1")["config"]
    assert cfg["noise_rot_deg"] == 0 and cfg["noise_trans"] == 0 and cfg["seed"] == 1
    assert load(runs / "r0_refiner_trained_with_noise__paper")["config"]["noise_rot_deg"] > 0


def test_variants_of_the_table_keep_their_run_names_and_feed_the_refiners(tmp_path):
    from sixdpose.pose.ablation import REFINER_VARIANTS, VARIANTS, run_ablation

    data = write_synthetic_dataset(tmp_path / "syn", n_images=1, two_instances_in_first=False)
    picked = {n: VARIANTS[n] for n in list(VARIANTS)[1:2]}  # as `--variants 1`: index 1, first picked
    table = run_ablation(data, data, tmp_path / "runs", profile="smoke", variants=picked, seeds=(0,),
                         refiner_variants=dict(list(REFINER_VARIANTS.items())[:1]), epochs=1, time_budget=0.0)
    assert list(table["network"]) == ["pose", "refiner"]
    assert sorted(p.name for p in (tmp_path / "runs").iterdir()) == ["1_centroid_offset",
                                                                     "r0_refiner_trained_with_noise__paper"]


def test_no_seed_is_refused(tmp_path):
    from sixdpose.pose.ablation import run_ablation

    data = write_synthetic_dataset(tmp_path / "syn", n_images=1, two_instances_in_first=False)
    with pytest.raises(ValueError, match="seeds"):
        run_ablation(data, data, tmp_path / "runs", profile="smoke", seeds=(), epochs=1)
