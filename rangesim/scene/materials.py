"""Object materials: a scene object's ``material`` table as a Mitsuba BSDF description.

The geometric scanner only uses an object's ``albedo`` (diffuse reflectance at the laser
wavelength); the rendered scanner path-traces the stripe through the object's BSDF. Types:

``diffuse``
    Lambertian; ``reflectance`` defaults to the object's ``albedo``.
``roughplastic`` / ``plastic``
    A diffuse base (``diffuse_reflectance``, default ``albedo``) under a dielectric coat
    (``int_ior``, default 1.49); ``alpha`` is the coat's GGX roughness (rough variant only).
``roughconductor`` / ``conductor``
    Metal: ``material`` names Mitsuba's measured conductor (default ``"Al"``; ``"none"`` is a
    perfect mirror) and ``alpha`` the GGX roughness (rough variant only).

Every material is two-sided (meshes from CAD files are not consistently wound, and an open
sheet must reflect on both sides); the laser wavelength (632.8-670 nm) reads the red
channel of Mitsuba's RGB spectra.
"""
from __future__ import annotations

from typing import Any, Mapping

from rangesim.core.errors import RangesimError

#: keys each material type accepts besides ``type``
MATERIAL_KEYS: dict[str, set[str]] = {
    "diffuse": {"reflectance"},
    "plastic": {"diffuse_reflectance", "int_ior", "ext_ior", "specular_reflectance", "nonlinear"},
    "roughplastic": {"diffuse_reflectance", "int_ior", "ext_ior", "specular_reflectance", "nonlinear",
                     "alpha", "distribution"},
    "conductor": {"material", "specular_reflectance"},
    "roughconductor": {"material", "specular_reflectance", "alpha", "distribution"},
}
#: keys holding reflectances in 0..1 (given as one number: the same in every channel)
_REFLECTANCES = {"reflectance", "diffuse_reflectance", "specular_reflectance"}


def check_material(material: Mapping[str, Any], where: str, source) -> dict[str, Any]:
    """Validate a material table and return a plain copy (with ``type`` filled in).

    Raises
    ------
    RangesimError
        Unknown type or key, or a value out of range, naming ``where`` in ``source``.
    """
    if not isinstance(material, Mapping):
        raise RangesimError(f"{where}.material must be a table", source=source)
    out = dict(material)
    kind = str(out.setdefault("type", "diffuse"))
    if kind not in MATERIAL_KEYS:
        raise RangesimError(
            f"{where}.material.type {kind!r} is unknown; use one of {', '.join(MATERIAL_KEYS)}", source=source
        )
    unknown = set(out) - MATERIAL_KEYS[kind] - {"type"}
    if unknown:
        raise RangesimError(
            f"{where}.material: unknown key(s) {', '.join(sorted(unknown))} for type {kind!r}; "
            f"accepted: {', '.join(sorted(MATERIAL_KEYS[kind]))}",
            source=source,
        )
    for key, value in out.items():
        if key in _REFLECTANCES or key == "alpha":
            if isinstance(value, bool) or not isinstance(value, (int, float)):
                raise RangesimError(f"{where}.material.{key} must be a number, got {value!r}", source=source)
            low, high = (1e-4, 1.0) if key == "alpha" else (0.0, 1.0)
            if not low <= float(value) <= high:
                raise RangesimError(f"{where}.material.{key} must lie in [{low}, {high}], got {value}", source=source)
        if key in ("int_ior", "ext_ior") and (isinstance(value, bool) or not isinstance(value, (int, float))
                                             or float(value) < 1.0):
            raise RangesimError(f"{where}.material.{key} must be a number >= 1, got {value!r}", source=source)
    return out


def bsdf_dict(material: Mapping[str, Any], albedo: float) -> dict[str, Any]:
    """The ``mi.load_dict`` description of a (checked) material, wrapped two-sided.

    Parameters
    ----------
    material : dict
        A table accepted by :func:`check_material` (empty: diffuse with ``albedo``).
    albedo : float
        The object's diffuse reflectance, the default of ``reflectance`` (diffuse) and
        ``diffuse_reflectance`` (plastics).
    """
    spec = dict(material) if material else {"type": "diffuse"}
    kind = spec.setdefault("type", "diffuse")
    if kind == "diffuse":
        spec.setdefault("reflectance", albedo)
    elif kind in ("plastic", "roughplastic"):
        spec.setdefault("diffuse_reflectance", albedo)
    elif kind in ("conductor", "roughconductor"):
        spec.setdefault("material", "Al")
    for key in _REFLECTANCES & set(spec):
        spec[key] = {"type": "rgb", "value": [float(spec[key])] * 3}
    if "alpha" in spec:
        spec["alpha"] = float(spec["alpha"])
    return {"type": "twosided", "bsdf": spec}
