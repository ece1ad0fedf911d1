"""The embedded training library: seeded synthetic materials tabulated on the 5 degree grid.

The linear basis of V&F Sec. 3.1 is learnt from a database of anisotropic BRDFs. gonio ships
a synthetic one so it works out of the box: :func:`library_specs` draws, from one seed, a
fixed list of analytic materials across seven families

============== =========================================================================
family          recipe (:mod:`gonio.brdf.models.analytic`)
============== =========================================================================
diffuse         Lambert, half of them with a faint very rough dielectric GGX lobe
plastic         Lambert + dielectric GGX (alpha 0.05-0.4), or Ashikhmin-Shirley, or Ward
metal           GGX with measured-like complex indices or a Schlick F0, slight anisotropy
paint           pigment Lambert under a clear coat (dielectric GGX), some with metal flakes
fabric          Lambert + Charlie sheen + an anisotropic thread highlight
brushed-metal   strongly anisotropic conductor GGX or Ward lobes
retro           Lambert + retro-reflective lobe, some with a surface glint
============== =========================================================================

Behind an option (``asymmetric=True``, not in the default library nor the shipped basis;
science.md 7.4) three more families have no twofold symmetry: their table at ``ph`` differs from
``ph + 180`` (:class:`~gonio.brdf.models.analytic.Tilted`, facets leaning one way)

============== =========================================================================
tilted-facet    a plastic or metal GGX lobe on facets tilted 5-30 deg (blazed, faceted; half
                as a renderer's constant normal map)
pile            Lambert + Charlie sheen (+ a rough coat) on fibres leaning 10-40 deg
sawtooth        Lambert + retro-reflective lobe (+ a glint) on facets tilted 10-35 deg
============== =========================================================================

They live in their own cache folder, so the default library's cache is shared.

Anisotropic materials are turned to a random orientation about the normal. Roughness never
goes below ``alpha = 0.05`` so the mirror peaks stay within a range the log remap of the basis
handles (math.md 4), and every reflectance stays below 1.

:func:`default_library` tabulates them (float32) on first use and caches one gonio table file
per material under :func:`library_cache_dir`, a folder keyed by a hash of the library version,
the seed and every material's parameters: any change to the recipe gives a new folder, so a
stale cache is never read. Users add their own measured tables with ``extra_dirs``.
"""

from __future__ import annotations

import difflib
import functools
import hashlib
import json
import math
import os
import zipfile
from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import platformdirs
from numpy.typing import NDArray

from gonio.brdf.models import analytic as bm
from gonio.brdf.tables import geometry as geo
from gonio.brdf.tables.table import BRDFTable

#: Bump when a recipe changes in a way the parameter hash would not see (e.g. a model's maths).
LIBRARY_VERSION = 1
DEFAULT_SEED = 2016
CHANNELS: tuple[str, ...] = ("R", "G", "B")
#: Materials per family; 175 in all (V&F train on 150 materials).
FAMILY_COUNTS: dict[str, int] = {
    "diffuse": 20,
    "plastic": 30,
    "metal": 25,
    "paint": 30,
    "fabric": 30,
    "brushed-metal": 25,
    "retro": 15,
}
#: Families without twofold symmetry, only with ``asymmetric=True`` (science.md 7.4).
ASYMMETRIC_FAMILY_COUNTS: dict[str, int] = {
    "tilted-facet": 40,
    "pile": 15,
    "sawtooth": 10,
}
MIN_ALPHA = 0.05
_MARKER = "complete.json"

# Approximate complex refractive indices (n, k) at about 650, 550 and 450 nm, rounded from
# published optical constants; good enough for plausible metal colours, not for metrology.
_METALS: dict[str, tuple[tuple[float, float, float], tuple[float, float, float]]] = {
    "gold": ((0.15, 0.40, 1.45), (3.60, 2.40, 1.70)),
    "silver": ((0.15, 0.12, 0.14), (4.20, 3.30, 2.50)),
    "copper": ((0.22, 0.95, 1.15), (3.60, 2.60, 2.40)),
    "aluminium": ((1.50, 0.96, 0.62), (7.70, 6.70, 5.40)),
    "chromium": ((3.10, 3.20, 2.30), (3.30, 3.30, 3.10)),
    "iron": ((2.90, 2.90, 2.50), (3.00, 2.90, 2.80)),
    "nickel": ((2.00, 1.80, 1.60), (3.70, 3.30, 2.80)),
    "titanium": ((2.70, 2.50, 2.10), (3.80, 3.40, 2.90)),
}


class LibraryError(ValueError):
    """A problem with the training library or a user table folder; says what to do."""


@dataclass(frozen=True)
class MaterialSpec:
    """One library material: a unique ``name``, its ``family`` and the analytic ``model``."""

    name: str
    family: str
    model: bm.BRDFModel

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready description (name, family and the model recipe)."""
        return {"name": self.name, "family": self.family, "model": bm.to_dict(self.model)}


# ---------------------------------------------------------------------------- recipes
def _colour(rng: np.random.Generator, lo: float, hi: float) -> tuple[float, float, float]:
    """A random RGB reflectance: a brightness in [lo, hi] times a mildly saturated hue."""
    level = rng.uniform(lo, hi)
    tint = rng.uniform(0.25, 1.0, size=3)
    tint /= tint.max()
    if rng.random() < 0.3:  # some near-greys, as real collections have many
        tint = 0.85 + 0.15 * tint
    return tuple(float(v) for v in np.clip(level * tint, 0.005, 0.95))  # type: ignore[return-value]


def _alpha(rng: np.random.Generator, lo: float, hi: float) -> float:
    """Log-uniform roughness in [lo, hi], never below :data:`MIN_ALPHA`."""
    return float(max(MIN_ALPHA, math.exp(rng.uniform(math.log(lo), math.log(hi)))))


def _orient(model: bm.BRDFModel, rng: np.random.Generator) -> bm.BRDFModel:
    """Turn an anisotropic material to a random orientation (isotropic ones are unchanged)."""
    if getattr(model, "isotropic", False):
        return model
    return bm.Rotated(model, float(rng.uniform(0.0, np.pi)), name=model.name)


def _dielectric(rng: np.random.Generator) -> bm.DielectricFresnel:
    return bm.DielectricFresnel(float(rng.uniform(1.4, 1.6)))


def _diffuse(rng: np.random.Generator, name: str) -> bm.BRDFModel:
    base = bm.Lambert(_colour(rng, 0.03, 0.9), name=name)
    if rng.random() < 0.5:
        return base
    a = _alpha(rng, 0.6, 1.0)
    glint = bm.GGX(a, a, _dielectric(rng), name="surface")
    # The 0.96 keeps diffuse plus surface reflection below the incident power.
    return bm.LobeSum((base, glint), weights=(0.96, float(rng.uniform(0.2, 1.0))), name=name)


def _plastic(rng: np.random.Generator, name: str) -> bm.BRDFModel:
    colour = _colour(rng, 0.05, 0.85)
    kind = rng.random()
    if kind < 0.6:
        a = _alpha(rng, MIN_ALPHA, 0.4)
        spec: bm.BRDFModel = bm.GGX(a, a, _dielectric(rng), name="coat")
        return bm.LobeSum((bm.Lambert(colour), spec), weights=(0.94, 1.0), name=name)
    if kind < 0.8:
        n = float(rng.uniform(20.0, 800.0))
        return bm.AshikhminShirley(n, n, float(rng.uniform(0.03, 0.06)), colour, name=name)
    a = _alpha(rng, 0.08, 0.4)
    spec = bm.Ward(a, a, float(rng.uniform(0.03, 0.1)), name="coat")
    return bm.LobeSum((bm.Lambert(colour), spec), weights=(0.9, 1.0), name=name)


def _metal(rng: np.random.Generator, name: str) -> bm.BRDFModel:
    a = _alpha(rng, MIN_ALPHA, 0.5)
    stretch = float(rng.uniform(1.0, 1.6))  # rolled or polished metals are slightly anisotropic
    fresnel: bm.Fresnel
    if rng.random() < 0.65:
        eta, k = _METALS[str(rng.choice(sorted(_METALS)))]
        fresnel = bm.ConductorFresnel(eta, k)
    else:
        fresnel = bm.SchlickFresnel(_colour(rng, 0.5, 0.95))
    masking = "correlated" if rng.random() < 0.7 else "separable"
    model = bm.GGX(a, min(2.0, a * stretch), fresnel, masking, name=name)  # type: ignore[arg-type]
    return _orient(model, rng)


def _paint(rng: np.random.Generator, name: str) -> bm.BRDFModel:
    pigment = bm.Lambert(_colour(rng, 0.03, 0.85))
    a = _alpha(rng, MIN_ALPHA, 0.2)
    coat = bm.GGX(a, a, bm.DielectricFresnel(1.5), name="clear-coat")
    if rng.random() < 0.4:  # metallic car paint: aluminium flakes under the coat
        fa = _alpha(rng, 0.15, 0.45)
        eta, k = _METALS["aluminium"]
        flakes = bm.GGX(fa, fa, bm.ConductorFresnel(eta, k), name="flakes")
        w = float(rng.uniform(0.1, 0.35))
        tint = _colour(rng, 0.5, 1.0)
        return bm.LobeSum(
            (pigment, flakes, coat),
            weights=(0.93 - w, tuple(w * t for t in tint), 1.0),
            name=name,
        )
    return bm.LobeSum((pigment, coat), weights=(0.93, 1.0), name=name)


def _fabric(rng: np.random.Generator, name: str) -> bm.BRDFModel:
    colour = _colour(rng, 0.05, 0.7)
    sheen = bm.Sheen(tuple(min(1.0, 0.3 + c) for c in colour), float(rng.uniform(0.3, 1.0)))
    if rng.random() < 0.7:
        ax = _alpha(rng, 0.1, 0.35)
        thread: bm.BRDFModel = bm.GGX(
            ax, min(1.0, ax * float(rng.uniform(2.0, 5.0))), _dielectric(rng), name="thread"
        )
    else:  # satin weave: a sharp anisotropic Phong lobe
        nu = float(rng.uniform(50.0, 300.0))
        thread = bm.AshikhminShirley(nu, nu / float(rng.uniform(5.0, 30.0)), 0.04, name="thread")
    weights = (0.75, float(rng.uniform(0.15, 0.4)), tuple(float(rng.uniform(0.3, 1.0)) * c + 0.2
                                                          for c in colour))
    return _orient(bm.LobeSum((bm.Lambert(colour), sheen, thread), weights=weights, name=name), rng)


def _brushed_metal(rng: np.random.Generator, name: str) -> bm.BRDFModel:
    along = _alpha(rng, MIN_ALPHA, 0.15)
    across = float(rng.uniform(0.25, 0.7))
    model: bm.BRDFModel
    if rng.random() < 0.7:
        eta, k = _METALS[str(rng.choice(["aluminium", "silver", "chromium", "iron", "nickel",
                                         "titanium", "copper", "gold"]))]
        model = bm.GGX(along, across, bm.ConductorFresnel(eta, k), name=name)
    else:
        model = bm.Ward(along, across, _colour(rng, 0.5, 0.9), name=name)
    return _orient(model, rng)


def _retro(rng: np.random.Generator, name: str) -> bm.BRDFModel:
    colour = _colour(rng, 0.05, 0.6)
    retro = bm.RetroReflective(_alpha(rng, 0.1, 0.4), _colour(rng, 0.3, 0.8))
    if rng.random() < 0.5:
        return bm.LobeSum((bm.Lambert(colour), retro), weights=(0.5, 0.5), name=name)
    a = _alpha(rng, 0.1, 0.3)
    glint = bm.GGX(a, a, bm.DielectricFresnel(1.5), name="surface")
    return bm.LobeSum((bm.Lambert(colour), retro, glint), weights=(0.45, 0.45, 1.0), name=name)


def _lean(model: bm.BRDFModel, rng: np.random.Generator, lo_deg: float,
          hi_deg: float, masking: str = "sawtooth") -> bm.BRDFModel:
    """Put ``model`` on facets tilted ``lo_deg``-``hi_deg`` toward a random azimuth.

    A dim diffuse floor (the risers and the ground between facets, albedo 0.01-0.04) keeps
    directions behind the facets from reading exactly 0, as no real specimen does.
    """
    tilted = bm.Tilted(model, math.radians(float(rng.uniform(lo_deg, hi_deg))),
                       float(rng.uniform(0.0, 2 * np.pi)), masking,  # type: ignore[arg-type]
                       name=model.name)
    floor = bm.Lambert(_colour(rng, 0.01, 0.04), name="risers")
    return bm.LobeSum((tilted, floor), name=model.name)


def _tilted_facet(rng: np.random.Generator, name: str) -> bm.BRDFModel:
    # A specular surface made of facets all leaning one way (blazed gratings, machined
    # sawtooth, faceted coatings): half plastics, half metals with a slight stretch; half of
    # them as a renderer's constant normal map (no shadowing), the shape such specimens have
    # when they come from a renderer.
    inner = _plastic(rng, name) if rng.random() < 0.5 else _metal(rng, name)
    return _lean(inner, rng, 5.0, 30.0, "sawtooth" if rng.random() < 0.5 else "none")


def _pile(rng: np.random.Generator, name: str) -> bm.BRDFModel:
    # Velvet or pile whose fibres lean one way: the sheen rises when looking against the nap.
    colour = _colour(rng, 0.05, 0.7)
    sheen = bm.Sheen(tuple(min(1.0, 0.3 + c) for c in colour), float(rng.uniform(0.3, 1.0)))
    lobes: tuple[bm.BRDFModel, ...] = (bm.Lambert(colour), sheen)
    weights: tuple[float, ...] = (0.7, float(rng.uniform(0.3, 0.8)))
    if rng.random() < 0.5:
        a = _alpha(rng, 0.3, 0.7)
        lobes += (bm.GGX(a, a, _dielectric(rng), name="fibre-coat"),)
        weights += (float(rng.uniform(0.3, 1.0)),)
    return _lean(bm.LobeSum(lobes, weights=weights, name=name), rng, 10.0, 40.0)


def _sawtooth(rng: np.random.Generator, name: str) -> bm.BRDFModel:
    # Retro-reflective sheeting or prisms on a sawtooth: the retro lobe is strong on one side.
    return _lean(_retro(rng, name), rng, 10.0, 35.0)


_ASYMMETRIC_RECIPES: dict[str, Callable[[np.random.Generator, str], bm.BRDFModel]] = {
    "tilted-facet": _tilted_facet,
    "pile": _pile,
    "sawtooth": _sawtooth,
}

_RECIPES: dict[str, Callable[[np.random.Generator, str], bm.BRDFModel]] = {
    "diffuse": _diffuse,
    "plastic": _plastic,
    "metal": _metal,
    "paint": _paint,
    "fabric": _fabric,
    "brushed-metal": _brushed_metal,
    "retro": _retro,
}


@functools.lru_cache(maxsize=4)
def _specs(seed: int, asymmetric: bool = False) -> tuple[MaterialSpec, ...]:
    """The default families, or (``asymmetric``) only the families without twofold symmetry."""
    counts = ASYMMETRIC_FAMILY_COUNTS if asymmetric else FAMILY_COUNTS
    recipes = _ASYMMETRIC_RECIPES if asymmetric else _RECIPES
    first = len(FAMILY_COUNTS) if asymmetric else 0
    out = []
    for f_index, (family, count) in enumerate(counts.items(), start=first):
        # One stream per family: changing one family's count or recipe leaves the others alone.
        rng = np.random.default_rng([seed, f_index])
        for k in range(count):
            name = f"{family}-{k:03d}"
            out.append(MaterialSpec(name, family, recipes[family](rng, name)))
    return tuple(out)


def library_specs(seed: int = DEFAULT_SEED, asymmetric: bool = False) -> list[MaterialSpec]:
    """The synthetic materials, deterministic for a given ``seed``.

    Parameters
    ----------
    seed : int
    asymmetric : bool
        Also the families without twofold symmetry (:data:`ASYMMETRIC_FAMILY_COUNTS`).

    Returns
    -------
    list of MaterialSpec
        :data:`FAMILY_COUNTS` materials per family, named ``"<family>-<NNN>"``, then (with
        ``asymmetric``) the :data:`ASYMMETRIC_FAMILY_COUNTS` ones.
    """
    out = list(_specs(int(seed)))
    return out + list(_specs(int(seed), True)) if asymmetric else out


def get_material(name: str, seed: int = DEFAULT_SEED) -> bm.BRDFModel:
    """The analytic model of library material ``name`` (e.g. ``"brushed-metal-004"``).

    Simulators use this to replay a library material exactly, without its table; the
    families without twofold symmetry (``"pile-003"``) are found too.
    """
    by_name = {s.name: s.model for s in library_specs(int(seed), asymmetric=True)}
    if name not in by_name:
        close = difflib.get_close_matches(name, by_name, n=3)
        hint = f"; did you mean {', '.join(close)}?" if close else "."
        raise LibraryError(
            f"no library material named {name!r}{hint} Names are <family>-<NNN> with families "
            f"{', '.join([*FAMILY_COUNTS, *ASYMMETRIC_FAMILY_COUNTS])}, or a table file "
            "(.npz); 'gonio library list' lists them all"
        )
    return by_name[name]


# ---------------------------------------------------------------------------- cache
def library_key(seed: int = DEFAULT_SEED, asymmetric: bool = False) -> str:
    """Hex digest identifying the library's content (version, seed, grid, every recipe).

    Caches derived from the library (the default basis) should include it in their own key.
    With ``asymmetric`` the digest of the families without twofold symmetry alone (their own
    cache folder; the default library's key is unchanged by the option).
    """
    payload: dict[str, Any] = {
        "version": LIBRARY_VERSION,
        "seed": int(seed),
        "grid": list(geo.TABLE_SHAPE),
        "dtype": "float32",
        "materials": [s.to_dict() for s in _specs(int(seed), asymmetric)],
    }
    if asymmetric:
        payload["part"] = "without twofold symmetry"
    return hashlib.sha256(json.dumps(payload, sort_keys=True).encode()).hexdigest()


def cache_root() -> Path:
    """gonio's user cache folder: ``$GONIO_CACHE_DIR`` if set, else the platform's user cache."""
    env = os.environ.get("GONIO_CACHE_DIR")
    return Path(env) if env else Path(platformdirs.user_cache_dir("gonio"))


def library_cache_dir(seed: int = DEFAULT_SEED, asymmetric: bool = False) -> Path:
    """Folder holding the tabulated library for ``seed`` (not created here); with
    ``asymmetric``, the folder of the families without twofold symmetry."""
    return (cache_root() / "library"
            / f"v{LIBRARY_VERSION}-{library_key(seed, asymmetric)[:16]}")


def _table_path(folder: Path, spec: MaterialSpec) -> Path:
    return folder / f"{spec.name}.npz"


def _write_compact(path: Path, compact: NDArray[np.float32], key: str) -> None:
    """Write one cached material atomically (uncompressed: writing is then ~10x faster)."""
    tmp = path.with_name(path.name + f".{os.getpid()}.part")
    with open(tmp, "wb") as fh:
        np.savez(fh, values_valid=compact, library_key=np.array(key))
    os.replace(tmp, path)


def _read_compact(path: Path, key: str) -> NDArray[np.float32] | None:
    """A cached material's compact values, or None when missing, damaged or stale."""
    try:
        with np.load(path, allow_pickle=False) as z:
            if str(z["library_key"]) != key:
                return None
            out = np.asarray(z["values_valid"], dtype=np.float32)
    except (OSError, KeyError, ValueError, EOFError, zipfile.BadZipFile):
        return None
    n_valid = int(geo.valid_mask().sum())
    if out.ndim != 3 or out.shape[0] != len(CHANNELS) or out.shape[1] not in (1, geo.N_PH) \
            or out.shape[2] != n_valid:
        return None
    return out


def build_library(seed: int = DEFAULT_SEED, progress: bool = False,
                  asymmetric: bool = False) -> list[Path]:
    """Tabulate every library material into :func:`library_cache_dir` (skipping cached ones).

    The cache holds, per material, an uncompressed ``.npz`` with ``values_valid``: the float32
    values at the valid cells, shape ``(3, P, 7861)`` with ``P = 1`` for isotropic materials
    (every ``ph`` slice is the same) and 72 otherwise, plus the ``library_key``. It is private
    to this module; use :func:`default_library` to read it. Files are written atomically, so
    concurrent builders and interrupted builds never leave a half-written file under a real
    name, and a damaged file is rebuilt.

    With ``asymmetric``, the families without twofold symmetry only, in their own folder.

    Returns
    -------
    list of Path
        One file per material, in :func:`library_specs` order.
    """
    folder = library_cache_dir(seed, asymmetric)
    key = library_key(seed, asymmetric)
    specs = _specs(int(seed), asymmetric)
    marker = folder / _MARKER
    paths = [_table_path(folder, s) for s in specs]
    if marker.is_file() and all(p.is_file() for p in paths):
        return paths
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise LibraryError(
            f"cannot create the library cache folder {folder} ({exc.strerror}); set "
            "GONIO_CACHE_DIR to a writable folder"
        ) from None
    todo: Iterable[tuple[MaterialSpec, Path]] = list(zip(specs, paths, strict=True))
    if progress:
        from tqdm import tqdm

        todo = tqdm(todo, desc="building BRDF library", unit="material")
    for spec, path in todo:
        if _read_compact(path, key) is None:
            compact = bm.tabulate_valid(spec.model).astype(np.float32)
            _write_compact(path, compact, key)
    marker.write_text(
        json.dumps({"seed": int(seed), "key": key, "materials": [s.name for s in specs]})
    )
    return paths


def iter_library(seed: int = DEFAULT_SEED, progress: bool = False,
                 asymmetric: bool = False) -> Iterator[BRDFTable]:
    """Yield the synthetic library's tables one at a time (builds the cache first if needed).

    Streaming keeps memory at one table (about 10 MB) for consumers that accumulate, such as
    a Gram-matrix basis build. With ``asymmetric``, the families without twofold symmetry only.
    """
    paths = build_library(seed, progress, asymmetric)
    key = library_key(seed, asymmetric)
    items: Iterable[tuple[MaterialSpec, Path]] = zip(_specs(int(seed), asymmetric), paths,
                                                     strict=True)
    if progress:
        from tqdm import tqdm

        items = tqdm(list(items), desc="loading BRDF library", unit="material")
    for spec, path in items:
        yield _cached_table(spec, path, key, int(seed))


def library_table(name: str, seed: int = DEFAULT_SEED) -> BRDFTable:
    """One library material's table, read from the cache (built first if needed).

    Reads one file instead of the whole library. Raises :class:`LibraryError` for an unknown
    name, suggesting close ones (as :func:`get_material`).
    """
    get_material(name, seed)  # the clear error for an unknown name
    for asymmetric in (False, True):
        paths = build_library(seed, asymmetric=asymmetric)
        for spec, path in zip(_specs(int(seed), asymmetric), paths, strict=True):
            if spec.name == name:
                return _cached_table(spec, path, library_key(seed, asymmetric), int(seed))
    raise LibraryError(f"{name!r} is not in the library cache {library_cache_dir(seed)}")


def _cached_table(spec: MaterialSpec, path: Path, key: str, seed: int) -> BRDFTable:
    compact = _read_compact(path, key)
    if compact is None:  # removed or damaged since the build: make it again
        compact = bm.tabulate_valid(spec.model).astype(np.float32)
        _write_compact(path, compact, key)
    provenance = {
        **bm.model_provenance(spec.model),
        "library": {"family": spec.family, "seed": seed, "version": LIBRARY_VERSION},
    }
    return BRDFTable(bm.expand_valid(compact), CHANNELS, spec.name, None, provenance)


def load_table_folder(folder: str | os.PathLike[str]) -> list[BRDFTable]:
    """Read every ``*.npz`` gonio table in ``folder`` (sorted by file name).

    Raises
    ------
    LibraryError
        The folder is missing or holds no ``.npz`` file.
    TableError
        A file is not a valid gonio table; the message names the file.
    """
    d = Path(folder)
    if not d.is_dir():
        raise LibraryError(
            f"extra library folder {d} does not exist; give a folder of gonio table .npz files"
        )
    files = sorted(d.glob("*.npz"))
    if not files:
        raise LibraryError(
            f"extra library folder {d} holds no .npz tables; save tables with BRDFTable.save"
        )
    return [BRDFTable.load(f) for f in files]


def default_library(
    extra_dirs: Sequence[str | os.PathLike[str]] = (),
    progress: bool = False,
    seed: int = DEFAULT_SEED,
    asymmetric: bool = False,
) -> list[BRDFTable]:
    """The training tables: the synthetic library (built and cached on first use) plus users'.

    Parameters
    ----------
    extra_dirs : sequence of folders
        Folders of gonio table ``.npz`` files to add (e.g. measured materials). They must have
        the library's channels (R, G, B) and names distinct from every other table.
    progress : bool
        Show a progress bar while building and loading.
    seed : int
        Library seed; the default reproduces the shipped library.
    asymmetric : bool
        Add the families without twofold symmetry (:data:`ASYMMETRIC_FAMILY_COUNTS`) after
        the default ones; off by default (science.md 7.4 measures what they cost).

    Returns
    -------
    list of BRDFTable
        Synthetic materials first (float32, ``(3, 72, 18, 18, 36)`` each, about 10 MB in
        memory), then the extra tables in folder order.
    """
    tables = list(iter_library(seed, progress))
    if asymmetric:
        tables += list(iter_library(seed, progress, asymmetric=True))
    seen = {t.name: "the synthetic library" for t in tables}
    for folder in extra_dirs:
        for table in load_table_folder(folder):
            source = table.provenance.get("file", str(folder))
            if tuple(table.channels) != CHANNELS:
                raise LibraryError(
                    f"{source}: table has channels {table.channels}, the library is "
                    f"{CHANNELS}; convert it to RGB or train a separate basis"
                )
            if table.name in seen:
                raise LibraryError(
                    f"{source}: material name {table.name!r} is already used by "
                    f"{seen[table.name]}; rename the table"
                )
            seen[table.name] = source
            tables.append(table)
    return tables


def build_progress(seed: int = DEFAULT_SEED) -> tuple[int, int]:
    """(materials already tabulated in the cache, materials in the library).

    Cheap (one ``stat`` per material): lets a daemon say how far the first library build has
    come while a job waits for it.
    """
    folder = library_cache_dir(seed)
    specs = _specs(int(seed))
    return sum(_table_path(folder, s).is_file() for s in specs), len(specs)
