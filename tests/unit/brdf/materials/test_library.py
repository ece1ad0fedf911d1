"""The embedded synthetic training library: content, realism, cache and user tables."""

from __future__ import annotations

import os
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from gonio.brdf.materials import library as lib
from gonio.brdf.models import analytic as bm
from gonio.brdf.tables import geometry as geo
from gonio.brdf.tables.table import BRDFTable, TableError


def walk(model: object) -> Iterator[object]:
    """Every model node of a (nested) LobeSum / Rotated tree."""
    yield model
    if isinstance(model, bm.LobeSum):
        for lobe in model.lobes:
            yield from walk(lobe)
    if isinstance(model, bm.Rotated):
        yield from walk(model.model)


@pytest.fixture
def small_library(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> Iterator[Path]:
    """A three-material library in a private cache folder, so cache tests stay fast and never
    touch the session's full library."""
    monkeypatch.setattr(lib, "FAMILY_COUNTS", {"diffuse": 2, "brushed-metal": 1})
    monkeypatch.setenv("GONIO_CACHE_DIR", str(tmp_path / "cache"))
    lib._specs.cache_clear()
    yield tmp_path
    lib._specs.cache_clear()


def test_specs_are_deterministic_and_cover_every_family() -> None:
    a, b = lib.library_specs(), lib.library_specs()
    assert a == b
    assert len(a) >= 150
    names = [s.name for s in a]
    assert len(set(names)) == len(names)
    families = {s.family for s in a}
    assert families == {"diffuse", "plastic", "metal", "paint", "fabric", "brushed-metal", "retro"}
    assert all(s.model.channels == ("R", "G", "B") for s in a)
    other = lib.library_specs(seed=lib.DEFAULT_SEED + 1)
    assert [s.name for s in other] == names
    assert [s.model for s in other] != [s.model for s in a]


def test_roughness_limited_and_anisotropy_randomly_oriented() -> None:
    specs = lib.library_specs()
    for spec in specs:
        for node in walk(spec.model):
            if isinstance(node, bm.GGX | bm.Ward):
                assert min(node.alpha_x, node.alpha_y) >= lib.MIN_ALPHA, spec.name
    brushed = [s.model for s in specs if s.family == "brushed-metal"]
    assert all(isinstance(m, bm.Rotated) and not m.isotropic for m in brushed)
    angles = np.array([m.angle for m in brushed if isinstance(m, bm.Rotated)])
    assert np.ptp(angles) > 2.0  # orientations spread over the half turn, not one value
    anisotropic = [s for s in specs if not getattr(s.model, "isotropic", True)]
    assert len(anisotropic) >= 50


def test_every_material_conserves_energy() -> None:
    """Directional albedo <= 1 at normal and 60 degree incidence for all materials."""
    for spec in lib.library_specs():
        for theta in (0.0, np.deg2rad(60.0)):
            wi = geo.spherical_to_direction(theta, 0.3)
            albedo = bm.directional_albedo(spec.model, wi, n_theta=200, n_phi=96)
            assert (albedo <= 1.0 + 1e-2).all(), (spec.name, albedo)
            assert (albedo > 1e-3).all(), (spec.name, albedo)


def test_get_material_replays_a_spec_and_suggests_names() -> None:
    spec = lib.library_specs()[42]
    assert lib.get_material(spec.name) == spec.model
    with pytest.raises(lib.LibraryError, match=r"no library material named 'metal-7'.*metal-"):
        lib.get_material("metal-7")


def test_library_key_depends_on_seed() -> None:
    assert lib.library_key() == lib.library_key()
    assert lib.library_key(1) != lib.library_key(2)
    assert lib.library_cache_dir().parent.parent == Path(os.environ["GONIO_CACHE_DIR"])


@pytest.mark.slow
def test_default_library_builds_once_and_matches_models() -> None:
    tables = lib.default_library()
    specs = lib.library_specs()
    assert [t.name for t in tables] == [s.name for s in specs]
    assert all(t.values.dtype == np.float32 and t.channels == lib.CHANNELS for t in tables)
    for k in (0, 60, len(specs) - 1):
        expected = bm.tabulate(specs[k].model)
        np.testing.assert_array_equal(tables[k].values, expected.values)
        assert tables[k].provenance["model"] == bm.to_dict(specs[k].model)
    marker = lib.library_cache_dir() / "complete.json"
    stamp = marker.stat().st_mtime_ns
    lib.build_library()
    assert marker.stat().st_mtime_ns == stamp  # cached: nothing rebuilt


def test_cache_is_reused_and_damaged_files_rebuilt(small_library: Path) -> None:
    first = lib.default_library()
    assert len(first) == 3
    paths = lib.build_library()
    assert all(p.parent == lib.library_cache_dir() for p in paths)
    stamps = [p.stat().st_mtime_ns for p in paths]
    assert [p.stat().st_mtime_ns for p in lib.build_library()] == stamps
    paths[2].write_bytes(b"not a zip file")
    again = lib.default_library()
    np.testing.assert_array_equal(again[2].values, first[2].values)
    assert lib.library_specs()[2].family == "brushed-metal"
    assert again[2].values.shape == (3, *geo.TABLE_SHAPE)


def test_progress_bar_when_asked(small_library: Path, capsys: pytest.CaptureFixture[str]) -> None:
    lib.default_library(progress=True)
    err = capsys.readouterr().err
    assert "building BRDF library" in err and "loading BRDF library" in err


def _save_user_table(folder: Path, name: str, channels: tuple[str, ...] = ("R", "G", "B")) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    table = bm.tabulate(bm.Lambert(0.3, channels=channels, name=name))
    return table.save(folder / f"{name}.npz")


def test_extra_dirs_add_user_tables(small_library: Path) -> None:
    folder = small_library / "mine"
    _save_user_table(folder, "my-felt")
    tables = lib.default_library(extra_dirs=[folder])
    assert [t.name for t in tables][-1] == "my-felt"
    assert len(tables) == 4


@pytest.mark.parametrize(
    ("setup", "error", "message"),
    [
        (lambda d: None, lib.LibraryError, r"does not exist"),
        (lambda d: d.mkdir(), lib.LibraryError, r"holds no \.npz tables"),
        (
            lambda d: (d.mkdir(), (d / "broken.npz").write_bytes(b"garbage")),
            TableError,
            r"broken\.npz: not a readable gonio table",
        ),
        (
            lambda d: _save_user_table(d, "grey", channels=("Y",)),
            lib.LibraryError,
            r"grey\.npz: table has channels \('Y',\)",
        ),
        (
            lambda d: _save_user_table(d, "diffuse-000"),
            lib.LibraryError,
            r"'diffuse-000' is already used by the synthetic library",
        ),
    ],
    ids=["missing", "empty", "corrupt", "channels", "duplicate"],
)
def test_bad_extra_dirs_are_reported(
    small_library: Path, setup: object, error: type[Exception], message: str
) -> None:
    folder = small_library / "user"
    setup(folder)  # type: ignore[operator]
    with pytest.raises(error, match=message):
        lib.default_library(extra_dirs=[folder])


def test_unwritable_cache_is_reported(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    blocker = tmp_path / "file"
    blocker.write_text("a file where the cache folder should go")
    monkeypatch.setenv("GONIO_CACHE_DIR", str(blocker))
    with pytest.raises(lib.LibraryError, match="set GONIO_CACHE_DIR to a writable folder"):
        lib.build_library()


def test_user_table_round_trip_is_valid_table(tmp_path: Path) -> None:
    path = _save_user_table(tmp_path, "check")
    assert BRDFTable.load(path).name == "check"


def test_one_material_read_from_the_cache_matches_the_library(small_library: Path) -> None:
    tables = lib.default_library()
    name = tables[1].name
    one = lib.library_table(name)
    assert one.name == name
    np.testing.assert_array_equal(one.values, tables[1].values)
    assert one.provenance == tables[1].provenance
    with pytest.raises(lib.LibraryError, match="no-such-material"):
        lib.library_table("no-such-material")


def test_unknown_material_message_reads_as_sentences() -> None:
    from gonio.brdf.materials.library import LibraryError, get_material

    with pytest.raises(LibraryError) as far:
        get_material("nosuch")
    assert "no library material named 'nosuch'. Names are <family>-<NNN>" in str(far.value)
    with pytest.raises(LibraryError, match=r"did you mean .*brushed-metal-003\? Names are"):
        get_material("brushed-metal-03")


def _turned_by_half(model: bm.BRDFModel, n: int = 300, seed: int = 8) -> tuple[np.ndarray, ...]:
    """The model's values at random direction pairs and at the same pairs turned by 180 deg."""
    rng = np.random.default_rng(seed)
    v = rng.normal(size=(2, n, 3))
    v[..., 2] = np.abs(v[..., 2]) + 0.05
    wi, wo = v / np.linalg.norm(v, axis=-1, keepdims=True)
    return (model.eval(wi, wo),
            model.eval(geo.rotate_z(wi, np.pi), geo.rotate_z(wo, np.pi)))


def test_asymmetric_families_lack_twofold_symmetry_and_stay_out_of_the_default() -> None:
    default = lib.library_specs()
    extra = lib.library_specs(asymmetric=True)[len(default):]
    assert lib.library_specs(asymmetric=True)[:len(default)] == default  # default untouched
    assert {s.family for s in extra} == set(lib.ASYMMETRIC_FAMILY_COUNTS)
    assert len(extra) == sum(lib.ASYMMETRIC_FAMILY_COUNTS.values())
    assert not {s.name for s in extra} & {s.name for s in default}
    for spec in default:  # every default material reads the same turned by half a turn
        a, b = _turned_by_half(spec.model)
        np.testing.assert_allclose(a, b, rtol=1e-9, atol=1e-12, err_msg=spec.name)
    for spec in extra:  # no material of the new families does
        a, b = _turned_by_half(spec.model)
        assert np.max(np.abs(np.log((a + 1e-3) / (b + 1e-3)))) > 0.1, spec.name
    # their key and cache folder are their own; the default library's do not move
    assert lib.library_key(asymmetric=True) != lib.library_key()
    assert lib.library_cache_dir(asymmetric=True) != lib.library_cache_dir()
    assert lib.get_material(extra[3].name) == extra[3].model


def test_asymmetric_families_conserve_energy() -> None:
    for spec in lib.library_specs(asymmetric=True)[len(lib.library_specs()):]:
        for theta in (0.0, np.deg2rad(60.0)):
            wi = geo.spherical_to_direction(theta, 0.3)
            albedo = bm.directional_albedo(spec.model, wi, n_theta=200, n_phi=96)
            assert (albedo <= 1.0 + 1e-2).all(), (spec.name, albedo)
            assert (albedo > 1e-3).all(), (spec.name, albedo)


def test_asymmetric_option_adds_its_tables_from_their_own_cache(
        small_library: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(lib, "ASYMMETRIC_FAMILY_COUNTS", {"pile": 1, "sawtooth": 1})
    lib._specs.cache_clear()
    plain = lib.default_library()
    both = lib.default_library(asymmetric=True)
    assert [t.name for t in both] == [t.name for t in plain] + ["pile-000", "sawtooth-000"]
    assert (lib.library_cache_dir(asymmetric=True) / "pile-000.npz").is_file()
    assert not (lib.library_cache_dir() / "pile-000.npz").exists()
    expected = bm.tabulate(lib.get_material("sawtooth-000"))
    np.testing.assert_array_equal(both[-1].values, expected.values)
    np.testing.assert_array_equal(lib.library_table("pile-000").values, both[-2].values)
