"""The named-material library: compositions and densities with their sources.

``xr.Material.named("water")`` builds one (:meth:`~xrayraster.Material.named`); scene files take
the names directly as an object's ``material`` (``[materials]`` entries of the same name win).
Each entry is ``(kind, value, density g/cm³, source)``, ``kind`` being ``"element"``,
``"formula"``, ``"mass_fractions"`` ({symbol: mass fraction}) or ``"oxides"`` ({oxide formula:
mass fraction}, for glasses). Plain data: :mod:`xrayraster.scene.materials` builds the Materials.

NIST Table 1/2 below are the element and compound tables of Hubbell & Seltzer, "Tables of X-Ray
Mass Attenuation Coefficients ... " (NISTIR 5632, https://physics.nist.gov/PhysRefData/XrayMassCoef/),
whose compositions are those of ICRU Report 37 and, for tissues, ICRU Report 44.
"""

from __future__ import annotations

LIBRARY: dict[str, tuple[str, object, float, str]] = {
    "air": ("mass_fractions", {"C": 0.000124, "N": 0.755268, "O": 0.231781, "Ar": 0.012827}, 1.205e-3,
            "NIST Table 2, 'Air, Dry (near sea level)'"),
    "water": ("mass_fractions", {"H": 0.111894, "O": 0.888106}, 1.000, "NIST Table 2, 'Water, Liquid'"),
    "pmma": ("mass_fractions", {"H": 0.080538, "C": 0.599848, "O": 0.319614}, 1.190,
             "NIST Table 2, 'Polymethyl Methacrylate (Lucite, Perspex)'"),
    "aluminium": ("element", "Al", 2.699, "NIST Table 1, Z = 13"),
    "epoxy": ("formula", "C21H24O4", 1.16,
              "DGEBA (bisphenol A diglycidyl ether, CAS 1675-54-3), C21H24O4; 1.16 g/cm³ at 25 °C, Sigma-Aldrich "
              "D3415 product specification (cured DGEBA/amine resins: 1.15-1.25)"),
    "carbon_fibre": ("element", "C", 1.76,
                     "PAN standard-modulus carbon fibre as pure carbon; 1.76 g/cm³, Toray TORAYCA T300 data sheet"),
    "e_glass": ("oxides", {"SiO2": 0.54, "Al2O3": 0.14, "B2O3": 0.10, "CaO": 0.175, "MgO": 0.045}, 2.54,
                "boron E-glass, a nominal composition inside the ranges of ASTM D578 (SiO2 52-56, Al2O3 12-16, "
                "B2O3 5-10, CaO 16-25, MgO 0-5 %); K. L. Loewenstein, The Manufacturing Technology of Continuous "
                "Glass Fibres, 3rd ed. (1993); density 2.54 g/cm³, ASM Handbook Vol. 21, Composites (2001)"),
    "titanium": ("element", "Ti", 4.540, "NIST Table 1, Z = 22"),
    "iron": ("element", "Fe", 7.874, "NIST Table 1, Z = 26"),
    "steel": ("mass_fractions", {"Fe": 0.9935, "Mn": 0.0045, "C": 0.0020}, 7.87,
              "AISI 1020 carbon steel, mid-range of C 0.17-0.23 % and Mn 0.30-0.60 %; 7.87 g/cm³, "
              "ASM Handbook Vol. 1 (1990), carbon and low-alloy steels"),
    "copper": ("element", "Cu", 8.960, "NIST Table 1, Z = 29"),
    "bone": ("mass_fractions", {"H": 0.034, "C": 0.155, "N": 0.042, "O": 0.435, "Na": 0.001, "Mg": 0.002,
                                "P": 0.103, "S": 0.003, "Ca": 0.225}, 1.920,
             "NIST Table 2, 'Bone, Cortical (ICRU-44)' (ICRU Report 44, 1989)"),
    "csi": ("formula", "CsI", 4.51, "CRC Handbook of Chemistry and Physics, physical constants of inorganic "
                                    "compounds: caesium iodide 4.51 g/cm³"),
    "gd2o2s": ("formula", "Gd2O2S", 7.34, "gadolinium oxysulfide (GOS); 7.34 g/cm³, M. Nikl, Meas. Sci. Technol. "
                                          "17 (2006) R37, Table 1"),
}

ALIASES = {
    "aluminum": "aluminium", "al": "aluminium", "perspex": "pmma", "lucite": "pmma", "acrylic": "pmma",
    "dgeba": "epoxy", "carbon_fiber": "carbon_fibre", "cfrp_fibre": "carbon_fibre", "eglass": "e_glass",
    "glass_fibre": "e_glass", "glass_fiber": "e_glass", "ti": "titanium", "fe": "iron", "cu": "copper",
    "cortical_bone": "bone", "bone_cortical": "bone", "cesium_iodide": "csi", "caesium_iodide": "csi",
    "gos": "gd2o2s",
}


def library_key(name: str) -> str | None:
    """The library entry ``name`` means (case, spaces and dashes ignored; aliases such as
    "aluminum" or "perspex" accepted), or None."""
    if not isinstance(name, str):
        return None
    key = name.strip().lower().replace(" ", "_").replace("-", "_")
    key = ALIASES.get(key, key)
    return key if key in LIBRARY else None
