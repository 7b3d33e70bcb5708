"""Small input files that tests in several folders share: a one-cell weave that meshes in a
fraction of a second, and a dataset file of a few tiny samples of the small scan."""

from __future__ import annotations

from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent

WEAVE_TOML = """
[weave]
weft_per_layer = 4
weft_layers = 3
warp_positions = 2
thickness = 2.8
margin_z = 0.4

[weave.sample]
cells = [1, 1]
points_per_section = 12
samples_per_mm = 2.0
seed = 7

[weave.distortion]
weft_node_mm = [0.0, 0.03, 0.02]
warp_node_mm = [0.03, 0.0, 0.02]

[weave.materials]
matrix = "resin"
weft = { fibre = "carbon_fibre", fibre_fraction = 0.6 }
warp = "pure_carbon"
tracers = [{ yarn = "weft_c0_l1_y2", material = "e_glass" }]

[materials.resin]
mass_fractions = { C = 0.404, H = 0.481, Cl = 0.019, O = 0.096 }
density = 1.08

[materials.pure_carbon]
element = "C"
density = 1.82
"""

# A few tiny samples of the small scan: 20 views of 16 × 32 onto 16 × 32 × 32 voxels of 0.46 mm.
TINY = f"""
base = "{ROOT / 'examples' / 'scan_small.toml'}"

[dataset]
count = {{count}}
seed = 7
splits = {{{{ train = 0.5, val = 0.25, test = 0.25 }}}}

[vary]
"geometry.num_views" = 20
"geometry.detector_shape" = [16, 32]
"geometry.pixel_size" = 0.92
"volume.shape" = [16, 32, 32]
"volume.voxel_size" = 0.46
"source.kvp" = {{{{ uniform = [38.0, 42.0] }}}}
"weave.weft_width_fraction" = {{{{ uniform = [0.85, 0.95] }}}}
"""


def tiny(tmp_path: Path, count: int = 4, layout: str | None = None, extra: str = "") -> Path:
    text = TINY.format(count=count).replace("[vary]", (f'layout = "{layout}"\n' if layout else "") + extra + "\n[vary]")
    path = tmp_path / "tiny.toml"
    path.write_text(text)
    return path
