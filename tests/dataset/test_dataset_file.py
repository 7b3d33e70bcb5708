"""Dataset files (docs/dataset.md): the file's checks, the distributions against their definitions,
deterministic draws and redraws, splits, the fingerprint, the plan, and the shipped examples."""

from __future__ import annotations

import copy
import math
from pathlib import Path

import numpy as np
import pytest

from xrayraster.core.errors import ConfigError
from xrayraster.dataset import differences, draw, fingerprint, format_plan, load_dataset_file, plan_rows
from xrayraster.dataset.distributions import Choice, Integer, LogUniform, Normal, Uniform, distribution_from
from xrayraster.pipeline import load_scan_file

ROOT = Path(__file__).resolve().parents[2]
EXAMPLES = ROOT / "examples"

# A quick base: a monochromatic source (no tube spectrum to model), a coarse mesh, a tiny grid.
BASE = {
    "weave": {"sample": {"cells": [1, 1], "points_per_section": 12, "samples_per_mm": 2.0}},
    "source": {"monochromatic_kev": 40.0, "photons_per_mm2_at_1m": 1e7},
    "geometry": {"source_to_origin": 35.0, "source_to_detector": 70.0, "detector_shape": [16, 32],
                 "pixel_size": 0.9, "num_views": 12},
    "volume": {"shape": [8, 16, 16], "voxel_size": 0.8},
}
VARY = {
    "weave.weft_width_fraction": {"uniform": [0.85, 0.99]},
    "geometry.source_to_origin": {"normal": [35.0, 1.0], "clip": [33.0, 37.0]},
    "scan.filter": {"choice": ["ram-lak", "hann"], "weights": [3, 1]},
    "weave.sample.cells": {"choice": [[1, 1], [1, 2]]},
    "geometry.num_views": 10,
}


def table(count=4, seed=3, vary=VARY, **dataset):
    return {**copy.deepcopy(BASE), "dataset": {"count": count, "seed": seed, **dataset}, "vary": copy.deepcopy(vary)}


@pytest.fixture(scope="module")
def dataset():
    return load_dataset_file(table(count=16, splits={"train": 0.5, "val": 0.25, "test": 0.25}))


def test_same_seed_and_index_draw_the_same_sample(dataset):
    again = load_dataset_file(table(count=16, splits={"train": 0.5, "val": 0.25, "test": 0.25}))
    a, b = draw(dataset, 5), draw(again, 5)
    assert a == b and a.values == b.values and a.table == b.table
    assert draw(dataset, 6).values != a.values and draw(dataset, 6).seed != a.seed
    looped = [draw(dataset, i) for i in range(10)]
    assert looped[5] == a


def test_growing_the_count_keeps_the_first_samples(dataset):
    small = load_dataset_file(table(count=8, splits={"train": 0.5, "val": 0.25, "test": 0.25}))
    assert [draw(small, i) for i in range(8)] == [draw(dataset, i) for i in range(8)]
    assert fingerprint(small) == fingerprint(dataset)


def test_a_draw_is_a_scan_table_with_its_values_and_seed(dataset):
    d = draw(dataset, 2)
    assert d.table["weave"]["weft_width_fraction"] == d.values["weave.weft_width_fraction"]
    assert d.table["geometry"]["num_views"] == 10 and d.scan.geometry.num_views == 10
    assert d.table["scan"]["seed"] == d.seed == d.table["weave"]["sample"]["seed"]
    assert d.scan.weave.sample.seed == d.seed and d.scan.options.seed == d.seed
    assert d.values["weave.sample.cells"] in ([1, 1], [1, 2])
    assert all(type(v) in (float, int, str, list) for v in d.values.values())  # plain Python, JSON-ready
    again = load_scan_file(copy.deepcopy(d.table), where="again")  # paths absolute: loads from anywhere
    assert again.geometry == d.scan.geometry


def test_around_is_the_bases_value_plus_or_minus_a_share():
    """{ around = r }: uniform over v(1 ± r) of the base's value (a fitted scan file's, docs/fit.md)."""
    dataset = load_dataset_file(table(count=200, vary={"geometry.source_to_origin": {"around": 0.1},
                                                       "source.photons_per_mm2_at_1m": {"around": 0.5}}))
    values = np.array([draw(dataset, i).values["geometry.source_to_origin"] for i in range(200)])
    assert 31.5 <= values.min() < 32.0 and 38.0 < values.max() <= 38.5  # 35 ± 3.5
    assert dataset.vary["source.photons_per_mm2_at_1m"] == Uniform(0.5e7, 1.5e7)
    clipped = load_dataset_file(table(vary={"geometry.source_to_origin": {"around": 0.1, "clip": [30.0, 36.0]}}))
    assert clipped.vary["geometry.source_to_origin"] == Uniform(31.5, 36.0)  # 35 ± 3.5, cut at 36
    for vary, message in [({"source.kvp": {"around": 0.1}}, "needs a non-zero number for 'source.kvp' in the base"),
                          ({"geometry.num_views": {"around": 1.5}}, "below 1"),
                          ({"geometry.num_views": {"around": 0.1, "weights": [1]}}, "takes only clip besides"),
                          ({"geometry.source_to_origin": {"around": 0.1, "clip": [0, 30]}}, "leaves nothing of"),
                          ({"geometry.source_to_origin": {"around": 0.1, "clip": [40, 30]}}, "empty range")]:
        with pytest.raises(ConfigError, match=message):
            load_dataset_file(table(vary=vary))


def test_scatter_is_a_key_a_dataset_varies():
    drawn = [draw(load_dataset_file(table(count=8, vary={"physics.scatter": {"choice": ["none", "kernel"]}})), i)
             for i in range(8)]
    assert {d.scan.realism.scatter for d in drawn} == {"none", "kernel"}
    assert all(d.scan.realism.scatter == d.values["physics.scatter"] for d in drawn)


def test_a_fixed_seed_is_kept():
    d = draw(load_dataset_file(table(vary={**VARY, "scan.seed": 7})), 0)
    assert d.table["scan"]["seed"] == 7 and d.table["weave"]["sample"]["seed"] == d.seed


def test_adding_a_key_leaves_the_other_draws(dataset):
    more = load_dataset_file(table(count=16, splits={"train": 0.5, "val": 0.25, "test": 0.25},
                                   vary={**VARY, "weave.weft_share": {"uniform": [0.5, 0.6]}}))
    a, b = draw(dataset, 3), draw(more, 3)
    assert all(b.values[k] == v for k, v in a.values.items()) and a.split == b.split and a.seed == b.seed


def test_nested_tables_mean_the_same_keys():
    nested = copy.deepcopy(VARY)
    nested["weave"] = {"weft_width_fraction": nested.pop("weave.weft_width_fraction"),
                       "sample": {"cells": nested.pop("weave.sample.cells")}}
    a, b = load_dataset_file(table(vary=nested)), load_dataset_file(table())
    assert a.vary == b.vary and draw(a, 1) == draw(b, 1)


def test_an_impossible_draw_is_redrawn_deterministically():
    # Half the draws of width fraction are above 1 (yarns wider than their spacing).
    vary = {"weave.weft_width_fraction": {"uniform": [0.9, 1.1]}}
    dataset = load_dataset_file(table(count=30, vary=vary))
    draws = [draw(dataset, i) for i in range(30)]
    redrawn = [d for d in draws if d.attempts > 1]
    assert redrawn and all(d.values["weave.weft_width_fraction"] <= 1 for d in draws)
    d = redrawn[0]
    assert len(d.redraws) == d.attempts - 1 and "weft_width_fraction" in d.redraws[0] and "\n" not in d.redraws[0]
    assert draw(dataset, d.index) == d and draw(dataset, d.index).redraws == d.redraws


def test_all_impossible_draws_name_the_keys_and_the_reason():
    with pytest.raises(ConfigError, match=r"\[vary\]: sample 0: none of 20 draws.*weave.weft_width_fraction.*"
                                          r"the last: .*weft_width_fraction"):
        load_dataset_file(table(vary={"weave.weft_width_fraction": {"uniform": [1.5, 2.0]}}))


def test_split_fractions():
    dataset = load_dataset_file(table(count=1, splits={"train": 0.7, "val": 0.2, "test": 0.1}))
    from xrayraster.dataset.dataset_file import _child, _split

    splits = [_split(dataset.splits, np.random.default_rng(_child(np.random.SeedSequence(3, spawn_key=(i,)),
                                                                   "split")).random()) for i in range(5000)]
    for name, fraction in dataset.splits.items():
        assert abs(splits.count(name) / 5000 - fraction) < 0.02
    assert draw(dataset, 0).split == splits[0]  # the split is the draw's


def test_uniform_and_loguniform_statistics():
    rng = np.random.default_rng(0)
    x = np.array([Uniform(2.0, 5.0).sample(rng) for _ in range(20000)])
    assert x.min() >= 2 and x.max() < 5
    assert abs(x.mean() - 3.5) < 0.03 and abs(x.var() - 9 / 12) < 0.03
    y = np.log([LogUniform(0.5, 2.0).sample(rng) for _ in range(20000)])
    assert abs(y.mean()) < 0.02 and abs(y.var() - np.log(4) ** 2 / 12) < 0.02


def test_normal_with_clip_is_the_truncated_normal():
    rng = np.random.default_rng(1)
    x = np.array([Normal(80.0, 2.0, (76.0, 84.0)).sample(rng) for _ in range(20000)])
    assert x.min() >= 76 and x.max() <= 84
    # Truncated at +-2 sigma: the variance is sigma^2 (1 - 2 a phi(a) / (2 Phi(a) - 1)), a = 2.
    a, phi = 2.0, math.exp(-2.0) / math.sqrt(2 * math.pi)
    expected = 4.0 * (1 - 2 * a * phi / math.erf(a / math.sqrt(2)))
    assert abs(x.mean() - 80) < 0.05 and abs(x.var() - expected) < 0.1
    free = np.array([Normal(1.0, 0.5).sample(rng) for _ in range(20000)])
    assert abs(free.mean() - 1) < 0.02 and abs(free.std() - 0.5) < 0.02


def test_integer_hits_both_ends_and_choice_follows_the_weights():
    rng = np.random.default_rng(2)
    ints = [Integer(3, 8).sample(rng) for _ in range(6000)]
    assert set(ints) == set(range(3, 9)) and all(type(i) is int for i in ints)
    choice = Choice(("a", [1, 2], {"shape": "ellipse"}), (1.0, 2.0, 1.0))
    draws = [choice.sample(rng) for _ in range(8000)]
    counts = np.array([sum(d == v for d in draws) for v in choice.values])
    expected = 8000 * np.array([0.25, 0.5, 0.25])
    assert ((counts - expected) ** 2 / expected).sum() < 13.8  # chi-square, 2 dof, p = 0.001


@pytest.mark.parametrize("value", [{"uniform": [1.0, 2.0]}, {"loguniform": [0.5, 2.0]}, {"normal": [1.0, 0.5]},
                                   {"normal": [1.0, 0.5], "clip": [0.0, 2.0]}, {"integer": [0, 100]},
                                   {"choice": [[2, 2], [3, 3]], "weights": [1.0, 2.0]}, [1, 2], "hann"])
def test_distributions_round_trip(value):
    d = distribution_from(value, "k.k", "here")
    assert d.to_dict() == value and distribution_from(d.to_dict(), "k.k", "here") == d


BAD = [
    ({"dataset": {"count": 0, "seed": 1}}, r"\[dataset\]: count must be an integer in \[1, "),
    ({"dataset": {"count": -3, "seed": 1}}, r"\[dataset\]: count"),
    ({"dataset": {"count": 2.5, "seed": 1}}, r"\[dataset\]: count"),
    ({"dataset": {"seed": 1}}, r"\[dataset\]: missing 'count'"),
    ({"dataset": {"count": 2, "seed": -1}}, r"\[dataset\]: seed"),
    ({"dataset": {"count": 2, "seed": 1, "colour": 1}}, r"\[dataset\]: unknown key\(s\) colour"),
    ({"dataset": {"count": 2, "seed": 1, "layout": "zarr"}}, r"\[dataset\]: layout must be one of tiff, nnunet"),
    ({"dataset": {"count": 2, "seed": 1, "splits": {"train": 0.8, "val": 0.1}}}, r"splits must sum to 1"),
    ({"dataset": {"count": 2, "seed": 1, "splits": {"train": 1.2, "val": -0.2}}}, r"splits.val must be >= 0"),
    ({"dataset": {"count": 2, "seed": 1, "splits": {"train": 0.5, "tets": 0.5}}}, r"splits: unknown key\(s\) tets"),
    ({"dataset": {"count": 2, "seed": 1, "name": "my-set"}}, r"\[dataset\]: name must be letters"),
    ({"dataset": {"count": 2, "seed": 1, "keep": ["volumes"]}}, r"\[dataset\]: keep must be"),
    ({"vary": {"source.kpv": 40}}, r"\[vary\]: 'source.kpv': no key 'kpv' in source"),
    ({"vary": {"sauce.kvp": 40}}, r"\[vary\]: 'sauce.kvp': no key 'sauce'"),
    ({"vary": {"geometry.num_views.x": 4}}, r"'geometry.num_views.x': the base scan's geometry.num_views is 12, not a"),
    ({"vary": {"geometry.detector_offset.x": 4}}, r"'geometry.detector_offset.x': geometry.detector_offset is a value"),
    ({"vary": {"objects.0.mesh": "a.stl"}}, r"'objects.0.mesh': objects is an array of tables"),
    ({"vary": {"pose.tilt_deg.2": {"uniform": [-1.0, 1.0]}}}, r"'pose.tilt_deg.2': pose.tilt_deg is a value.*give the "
     r"array in the base scan \(pose.tilt_deg = \[...\]\)"),
    ({"vary": {"geometry.detector_shape.2": 4}}, r"'geometry.detector_shape.2': the base scan's geometry.detector_shape "
     r"has 2 entries; name one by its index, 0 to 1 \(got '2'\)"),
    ({"vary": {"geometry.detector_shape": [16, 32], "geometry.detector_shape.0": 8}}, r"'geometry.detector_shape.0' lies inside"),
    ({"vary": {"weave.sample": {"choice": [{}]}, "weave.sample.seed": 1}}, r"'weave.sample.seed' lies inside"),
    ({"vary": {"source.kvp": {"uniform": [40, 41], "clip": [40, 41]}}}, r"'source.kvp': unknown key\(s\) clip"),
    ({"vary": {"source.kvp": {"uniform": [40, 41], "integer": [1, 2]}}}, r"'source.kvp' must give exactly one"),
    ({"vary": {"source.kvp": {"uniform": [5.0, 5.0]}}}, r"'source.kvp' uniform = \[5.0, 5.0\] is an empty range"),
    ({"vary": {"source.kvp": {"uniform": [6.0, 5.0]}}}, r"'source.kvp' uniform = \[6.0, 5.0\] is an empty range"),
    ({"vary": {"source.kvp": {"uniform": [6.0]}}}, r"'source.kvp' uniform must be \[low, high\]"),
    ({"vary": {"source.kvp": {"uniform": "40"}}}, r"'source.kvp' uniform must be"),
    ({"vary": {"source.kvp": {"loguniform": [0.0, 5.0]}}}, r"'source.kvp' loguniform .* must be > 0"),
    ({"vary": {"source.kvp": {"normal": [40.0, 0.0]}}}, r"'source.kvp' normal .* sigma must be > 0"),
    ({"vary": {"source.kvp": {"normal": [40.0, 1.0], "clip": [41.0, 39.0]}}}, r"'source.kvp' clip .* empty range"),
    ({"vary": {"source.kvp": {"normal": [40.0, 1.0], "clip": [90.0, 91.0]}}}, r"'source.kvp' clip .* impossible"),
    ({"vary": {"weave.sample.seed": {"integer": [5, 5]}}}, r"'weave.sample.seed' integer .* empty range"),
    ({"vary": {"weave.sample.seed": {"integer": [0.5, 5]}}}, r"'weave.sample.seed' integer\[0\] must be an integer"),
    ({"vary": {"scan.filter": {"choice": []}}}, r"'scan.filter' choice must be a non-empty array"),
    ({"vary": {"scan.filter": {"choice": ["hann"], "weights": [1, 2]}}}, r"'scan.filter' weights must be an array of 1"),
    ({"vary": {"scan.filter": {"choice": ["hann", "cosine"], "weights": [1, -2]}}}, r"weights\[1\] must be >= 0"),
    ({"vary": {"scan.filter": {"choice": ["hann", "cosine"], "weights": [0, 0]}}}, r"'scan.filter' weights are all 0"),
    ({"vary": {"scan.filter": {"choice": ["hann", "nope"], "weights": [0, 1]}}}, r"none of 20 draws.*filter must be"),
    ({"vary": {"source": {}}}, r"'source' is an empty table"),
    ({"colour": 1}, r"unknown key\(s\) colour"),
]


@pytest.mark.parametrize("edit, message", BAD, ids=[m for _, m in BAD])
def test_bad_dataset_files_name_the_key(edit, message):
    data = table()
    for name, value in edit.items():
        data[name] = value if name != "vary" else {**value}
    with pytest.raises(ConfigError, match=message) as error:
        load_dataset_file(data)
    assert "\n" not in str(error.value)


def test_base_and_inline_tables_are_exclusive(tmp_path):
    with pytest.raises(ConfigError, match=r"not both"):
        load_dataset_file({**table(), "base": "scan_small.toml"}, base_dir=EXAMPLES)
    with pytest.raises(ConfigError, match=r"no base scan"):
        load_dataset_file({"dataset": {"count": 1, "seed": 0}})
    with pytest.raises(ConfigError, match=r"nowhere.toml: no such file"):
        load_dataset_file({"base": "nowhere.toml", "dataset": {"count": 1, "seed": 0}}, base_dir=tmp_path)


def test_a_base_file_is_relative_to_the_dataset_file_and_its_paths_made_absolute(tmp_path):
    scene = EXAMPLES / "bracket_ct.toml"
    (tmp_path / "sub").mkdir()
    (tmp_path / "sub" / "meshes").symlink_to(EXAMPLES / "meshes", target_is_directory=True)
    (tmp_path / "sub" / "scan.toml").write_text(scene.read_text() + "\n[volume]\nshape = [8, 8, 8]\nvoxel_size = 1.0\n")
    (tmp_path / "ds.toml").write_text('base = "sub/scan.toml"\n[dataset]\ncount = 2\nseed = 0\n'
                                      '[vary]\n"objects.0.translate" = { choice = [[0, 0, 0], [0, 0, 1]] }\n')
    dataset = load_dataset_file(tmp_path / "ds.toml")
    assert dataset.name == "ds" and Path(dataset.base["objects"][0]["mesh"]).is_absolute()
    assert draw(dataset, 1).values["objects.0.translate"] in ([0, 0, 0], [0, 0, 1])


def test_fingerprint_ignores_count_and_names_every_change(dataset):
    base = fingerprint(dataset)
    assert fingerprint(load_dataset_file(table(count=3, splits={"train": 0.5, "val": 0.25, "test": 0.25}))) == base
    changes = {
        "seed": table(seed=4, splits={"train": 0.5, "val": 0.25, "test": 0.25}),
        "layout": table(layout="hdf5", splits={"train": 0.5, "val": 0.25, "test": 0.25}),
        "splits": table(splits={"train": 0.5, "val": 0.5}),
        "keep": table(keep=["meshes"], splits={"train": 0.5, "val": 0.25, "test": 0.25}),
        "name": table(name="other", splits={"train": 0.5, "val": 0.25, "test": 0.25}),
        "vary scan.filter": table(vary={**VARY, "scan.filter": "hann"},
                                  splits={"train": 0.5, "val": 0.25, "test": 0.25}),
    }
    for key, data in changes.items():
        other = load_dataset_file(data)
        assert fingerprint(other) != base, key
        assert any(line.startswith(key) for line in differences(dataset, other)), (key, differences(dataset, other))
    data = table(splits={"train": 0.5, "val": 0.25, "test": 0.25})
    data["source"]["monochromatic_kev"] = 41.0
    assert differences(dataset, load_dataset_file(data)) == ["base source.monochromatic_kev: 40.0 -> 41.0"]
    assert differences(dataset, dataset) == []


def test_plan_rows(dataset):
    rows = plan_rows(load_dataset_file(table(count=3)))
    assert [r["index"] for r in rows] == [0, 1, 2]
    assert all(r["seconds"] > 0 and r["bytes"] == 8 * 16 * 16 * 5 and r["attempts"] >= 1 for r in rows)
    text = format_plan(rows)
    assert "scan.filter" in text and "3 samples" in text and len(text.splitlines()) == 5


def test_an_entry_of_an_array_is_drawn_apart_from_the_others():
    """"pose.tilt_deg.2" varies the tilt about z alone: drawn in its range per sample, the other
    entries the base's, and the scan file posed with it."""
    data = table(vary={"pose.tilt_deg.2": {"uniform": [-1.6, 1.6]}, "pose.offset_mm.0": {"uniform": [-0.26, 0.26]}})
    data["pose"] = {"offset_mm": [0.0, 0.5, 0.0], "tilt_deg": [3.0, 0.0, 0.0]}
    dataset = load_dataset_file(data)
    draws = [draw(dataset, i) for i in range(4)]
    tilts = [d.values["pose.tilt_deg.2"] for d in draws]
    assert all(-1.6 <= t < 1.6 for t in tilts) and len(set(tilts)) == 4
    for d in draws:
        assert d.table["pose"]["tilt_deg"] == [3.0, 0.0, d.values["pose.tilt_deg.2"]]
        assert d.table["pose"]["offset_mm"] == [d.values["pose.offset_mm.0"], 0.5, 0.0]
        assert d.scan.pose.tilt_deg == (3.0, 0.0, d.values["pose.tilt_deg.2"])
    assert dataset.base["pose"] == {"offset_mm": [0.0, 0.5, 0.0], "tilt_deg": [3.0, 0.0, 0.0]}  # the base unchanged


def test_the_examples_load_and_every_small_sample_draws():
    big = load_dataset_file(EXAMPLES / "dataset.toml")
    assert big.count == 1000 and big.layout == "nnunet" and big.name == "angle_interlock"
    pose = draw(big, 0).scan.pose  # the reference scans' ±0.26 mm and ±1.6° on every axis
    assert all(0 < abs(x) < 0.26 for x in pose.offset_mm) and all(0 < abs(a) < 1.6 for a in pose.tilt_deg)
    small = load_dataset_file(EXAMPLES / "dataset_small.toml")
    assert small.count == 8 and small.name == "dataset_small"
    for i in range(small.count):
        d = draw(small, i)
        assert d.scan.volume.shape == (64, 64, 64) and d.scan.geometry.num_views == 60


def test_a_drawn_sample_scans(gl, cl):
    import xrayraster as xr

    d = draw(load_dataset_file(table()), 0)
    result = xr.scan(d.scan)
    assert result.labels.data.shape == (8, 16, 16) and result.metadata["seed"] == d.seed
