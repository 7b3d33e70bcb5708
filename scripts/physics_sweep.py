"""Part 1 of bench_physics: the spectral sum on synthetic path lengths, timed against bins,
channels and detector size, with its error against a float64 evaluation from the definition.

The materials, the pixel count of the error sample and :func:`reference_transmission` are shared
with part 2 (:mod:`scripts.physics_radiograph`).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

import xrayraster as xr
from scripts import common
from scripts import weave_scene as weave
from scripts.common import best_of, say
from xrayraster.physics import beer_lambert
from xrayraster.physics.radiograph import BIN_TOLERANCE, radiograph

# -- part 1 materials and path-length ranges (mm), channel c uses the first c entries
SWEEP_MATERIALS = [
    (xr.Material.element("C", 1.80, name="carbon fibre"), 8.0),
    (xr.Material.from_mass_fractions({"O": 0.4725, "Si": 0.2540, "Ca": 0.1620, "Al": 0.0741, "B": 0.0220,
                                      "Mg": 0.0154}, 2.55, name="E-glass"), 3.0),
    (xr.Material.from_formula("C21H24O4", 1.16, name="epoxy (DGEBA)"), 10.0),
    (xr.Material.element("Al", 2.70, name="aluminium"), 4.0),
]
REF_PIXELS = 2000
NOISE_S_PER_PX_BIN = 1e-8  # first guess for the noise skip rule (measured ~5e-9 s here), then measured


def regroup(spectrum: xr.Spectrum, bins: int) -> xr.Spectrum:
    """``bins`` contiguous groups of the non-empty bins with about equal photon counts."""
    e, n = spectrum.energies, spectrum.fluence
    e, n = e[n > 0], n[n > 0]
    cum = np.cumsum(n) / n.sum()
    group = np.minimum((cum * bins - 1e-12).astype(int), bins - 1)
    group = np.maximum.accumulate(group)
    ids = np.unique(group)
    if len(ids) < bins:  # cumulative cut can leave a group empty: split by index instead
        group = np.minimum(np.arange(len(e)) * bins // len(e), bins - 1)
        ids = np.unique(group)
    photons = np.array([n[group == g].sum() for g in ids])
    energies = np.array([(e[group == g] * n[group == g]).sum() for g in ids]) / photons
    return xr.Spectrum.from_arrays(energies, photons, f"{spectrum.description}; regrouped into {len(ids)} bins")


def reference_transmission(lengths_mm: np.ndarray, mu: np.ndarray, photons: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """float64 Σ_b w_b N_b exp(−Σ_c μ_cb L_c) / Σ_b w_b N_b, straight from the definition.

    ``lengths_mm`` (channels, m), ``mu`` (channels, bins)."""
    lengths_mm = np.asarray(lengths_mm, np.float64)
    num = np.zeros(lengths_mm.shape[1])
    for b in range(mu.shape[1]):
        exponent = np.zeros(lengths_mm.shape[1])
        for c in range(mu.shape[0]):
            exponent += mu[c, b] * lengths_mm[c]
        num += weights[b] * photons[b] * np.exp(-exponent)
    return num / float(np.sum(weights * photons))


def sweep(sizes, channels_list, bins_list, repeats, budget_s, noise_budget_s):
    say("\n== Part 1: spectral sum (synthetic path lengths) ==")
    base = xr.Spectrum.from_tube(80, "W", filters={"Al": 2.0}, bin_kev=0.25)
    say(f"spectrum: {base.description}; {int(np.count_nonzero(base.fluence))} non-empty bins, regrouped to B bins")
    say("materials (channel order, synthetic length range): "
        + "; ".join(f"{m.name} {m.density:g} g/cm³ 0–{r:g} mm" for m, r in SWEEP_MATERIALS))
    say("detector: integrating, no scintillator (η = 1, w = E); factor: per-pixel photon factor of a cone-beam view")
    say(f"error: max |T − T_ref| / T_ref on {REF_PIXELS} seeded pixels, T_ref float64 from the definition "
        f"(all B bins; radiograph() trims bins carrying ≤ {BIN_TOLERANCE:g} of the open-beam signal)")
    hdr = (f"{'det':>5} {'ch':>2} {'B':>4} │ {'expected_signal s':>17} {'max rel err':>11} │ {'radiograph() s':>14} {'bins':>4} "
           f"{'max rel err':>11} │ {'sampled_signal s':>16} │ {'Mpx·bins/s':>10}")
    say(hdr)
    spectra = {b: regroup(base, b) for b in bins_list}
    det = xr.Detector()
    records, skipped = [], []
    rate = {}  # last measured seconds per (pixel·bin) of sampled_signal, for the skip rule
    for n in sizes:
        geom = weave.geometry(n)
        factor = beer_lambert.pixel_photon_factor(geom, 0)
        rng = np.random.default_rng([7, n])
        lengths_all = np.empty((len(SWEEP_MATERIALS), n, n), np.float32)
        for c, (_, top) in enumerate(SWEEP_MATERIALS):
            lengths_all[c] = rng.random((n, n), dtype=np.float32) * np.float32(top)
        rc = weave.sample_pixels(n, REF_PIXELS)
        for channels in channels_list:
            lengths = lengths_all[:channels]
            mats = [m for m, _ in SWEEP_MATERIALS[:channels]]
            sample = lengths[:, rc[:, 0], rc[:, 1]]
            for bins in bins_list:
                spec = spectra[bins]
                e, photons = spec.energies, spec.fluence
                mu = np.stack([m.attenuation(e) for m in mats])
                w = det.weights(e)
                ref = reference_transmission(sample, mu, photons, w)
                work = n * n * len(e)
                rec = {"detector": n, "channels": channels, "bins": len(e)}
                # expected_signal
                t, sig = best_of(lambda: beer_lambert.expected_signal(lengths, mu, photons, w, factor), repeats, budget_s)
                trans = sig[rc[:, 0], rc[:, 1]] / (float((photons * w).sum()) * factor[rc[:, 0], rc[:, 1]])
                rec["expected_signal_s"] = t
                rec["expected_signal_max_rel_err"] = float(np.max(np.abs(trans - ref) / ref))
                del sig
                # radiograph(): trimming, μ table, sum, normalisation
                t, rad = best_of(lambda: radiograph(lengths, mats, spec, det, factor, output="transmission"), repeats, budget_s)
                img = rad.image[rc[:, 0], rc[:, 1]].astype(np.float64)
                rec["radiograph_s"] = t
                rec["radiograph_bins"] = rad.bins
                rec["radiograph_max_rel_err"] = float(np.max(np.abs(img - ref) / ref))
                del rad
                # sampled_signal (noise)
                pred = rate.get("noise", NOISE_S_PER_PX_BIN) * work  # the per-(pixel·bin) cost dominates
                if pred > noise_budget_s:
                    rec["sampled_signal_s"] = None
                    skipped.append(f"sampled_signal {n}² {channels} ch {len(e)} bins (predicted {pred:.1f} s > {noise_budget_s:g} s)")
                else:
                    gen = np.random.default_rng(1)
                    t, _ = best_of(lambda: beer_lambert.sampled_signal(lengths, mu, photons, det.efficiency(e), e, factor, False, gen),
                                   repeats, budget_s)
                    if work >= 2**20:  # small calls are overhead-bound: they would mispredict
                        rate["noise"] = t / work
                    rec["sampled_signal_s"] = t
                records.append(rec)
                ns = rec["sampled_signal_s"]
                say(f"{n:>5} {channels:>2} {len(e):>4} │ {rec['expected_signal_s']:>17.4f} {rec['expected_signal_max_rel_err']:>11.2e} │ "
                    f"{rec['radiograph_s']:>14.4f} {rec['radiograph_bins']:>4} {rec['radiograph_max_rel_err']:>11.2e} │ "
                    f"{'skipped' if ns is None else f'{ns:.4f}':>16} │ {work / 1e6 / rec['expected_signal_s']:>10.0f}")
        del lengths_all
    if skipped:
        say("skipped (time budget): " + "; ".join(skipped))
    return records, skipped, base.description


def plot(plt, records: list[dict], plots_dir: Path, suffix: str) -> Path | None:
    """Time and error against bins, one column per detector size; None without records."""
    sizes = sorted({r["detector"] for r in records})
    if not sizes:
        return None
    fig, axes = plt.subplots(2, len(sizes), figsize=(5 * len(sizes), 8.5), squeeze=False)
    for j, n in enumerate(sizes):
        ax, ax2 = axes[0, j], axes[1, j]
        for ch in sorted({r["channels"] for r in records}):
            rs = sorted((r for r in records if r["detector"] == n and r["channels"] == ch), key=lambda r: r["bins"])
            c = f"C{ch - 1}"
            x = [r["bins"] for r in rs]
            ax.plot(x, [r["expected_signal_s"] for r in rs], "o-", color=c, label=f"{ch} ch expected_signal")
            ax.plot(x, [r["radiograph_s"] for r in rs], "s--", color=c, label=f"{ch} ch radiograph()", alpha=0.7)
            ns = [(r["bins"], r["sampled_signal_s"]) for r in rs if r["sampled_signal_s"] is not None]
            if ns:
                ax.plot(*zip(*ns), "^:", color=c, label=f"{ch} ch sampled_signal (noise)", alpha=0.6)
            ax2.plot(x, [max(r["expected_signal_max_rel_err"], 1e-17) for r in rs], "o-", color=c, label=f"{ch} ch expected_signal")
            ax2.plot(x, [max(r["radiograph_max_rel_err"], 1e-17) for r in rs], "s--", color=c, label=f"{ch} ch radiograph()", alpha=0.7)
            for r in rs:  # error printed beside the time
                ax.annotate(f"{r['radiograph_max_rel_err']:.0e}", (r["bins"], r["radiograph_s"]), textcoords="offset points",
                            xytext=(3, -9), fontsize=6, color=c)
        common.log_axes(ax, "energy bins B", "time (s), best of ≤ 3",
                        f"{n}² detector: time (labels: radiograph() max rel. error)", legend=None)
        common.log_axes(ax2, "energy bins B", "max relative transmission error vs float64", f"{n}² detector: error",
                        legend=None)
    axes[0, 0].legend(fontsize=6, ncol=1)
    fig.suptitle("spectral sum: time vs energy bins (synthetic path lengths; 80 kVp W, 2 mm Al regrouped; η = 1)", fontsize=10)
    fig.tight_layout()
    return common.save(fig, plots_dir / f"bench_physics_spectral_sum{suffix}.png")
