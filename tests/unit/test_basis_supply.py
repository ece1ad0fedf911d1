"""The process's one reconstruction basis: made once whoever asks, known without a load.

Through the real :class:`gonio.basis_supply.BasisSupply` with small random bases (saved as the
default basis' cache file where the default supply is under test, in a cache folder of the
test's own); what is asserted is how often the basis is made and what is recorded, never times.
"""

from __future__ import annotations

import os
import threading
from pathlib import Path
from typing import Any

import pytest

from gonio.basis_supply import BasisSupply
from gonio.brdf.reconstruction.basis import Basis, default_basis_path
from gonio.plans.dryrun import ASYMMETRIC_BASIS_BUILD_S, BASIS_BUILD_S, BasisSymmetry
from gonio.plans.models import ExposureSettings, UniformPlan
from gonio.store import JobStore
from tests.unit.brdf.reconstruction.test_reconstruct import random_basis
from tests.unit.brdf.reconstruction.test_reconstruct_joint import _with_prior

FAST = ExposureSettings(exposure_s=0.002, light_settle_s=0.0, dark="once")
HALF = UniformPlan(rotations=4, span_deg=180, exposure=FAST)
FULL = UniformPlan(rotations=4, span_deg=360, exposure=FAST)
EVEN = _with_prior(random_basis(6, seed=1), {0: 1.0, 2: 0.5})
ODD = _with_prior(random_basis(6, seed=2), {0: 1.0, 1: 0.3, 2: 0.5})


def _cache_with(monkeypatch: pytest.MonkeyPatch, tmp_path: Path, basis: Basis) -> Path:
    """This test's own cache folder, holding ``basis`` as the built default basis."""
    monkeypatch.setenv("GONIO_CACHE_DIR", str(tmp_path / "cache"))
    path = default_basis_path()
    path.parent.mkdir(parents=True, exist_ok=True)
    basis.save(path)
    return path


def test_callers_at_once_share_one_load() -> None:
    entered, release = threading.Event(), threading.Event()
    calls: list[str] = []

    def slow() -> Basis:
        calls.append(threading.current_thread().name)
        entered.set()
        release.wait(60)
        return EVEN

    supply = BasisSupply(slow)
    got: list[Any] = []
    threads = [threading.Thread(target=lambda: got.append(supply.get())) for _ in range(3)]
    threads[0].start()
    assert entered.wait(60)
    for t in threads[1:]:
        t.start()
    release.set()
    for t in threads:
        t.join(60)
    assert len(calls) == 1  # the others waited for the first caller's basis
    assert len(got) == 3 and all(b is EVEN for b in got)
    assert supply.get() is EVEN and len(calls) == 1


def test_a_provider_that_failed_is_asked_again() -> None:
    answers: list[Basis | Exception] = [OSError("basis file unreadable"), EVEN]

    def provider() -> Basis:
        answer = answers.pop(0)
        if isinstance(answer, Exception):
            raise answer
        return answer

    supply = BasisSupply(provider)
    with pytest.raises(OSError, match="unreadable"):
        supply.get()
    assert supply.symmetry() is None  # nothing was had
    assert supply.get() is EVEN and answers == []


def test_a_provider_is_never_called_just_to_look() -> None:
    supply = BasisSupply(lambda: pytest.fail("called to look"))
    assert not supply.is_default and not supply.build_needed()
    assert supply.symmetry() is None
    assert supply.wait_report("", 60.0) == ("loading the reconstruction basis", None)


def test_a_provider_s_basis_is_known_once_had() -> None:
    supply = BasisSupply(lambda: ODD)
    supply.get()
    assert supply.symmetry() == BasisSymmetry.of(ODD)
    assert supply.symmetry() is not None and not supply.symmetry().half_turn_periodic  # type: ignore[union-attr]


def test_the_default_basis_is_kept_until_its_cache_file_changes(
        monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    path = _cache_with(monkeypatch, tmp_path, EVEN)
    supply = BasisSupply()
    assert supply.is_default and not supply.build_needed()
    # Known from the file, before any load.
    assert supply.symmetry() == BasisSymmetry.of(EVEN)
    first = supply.get()
    assert first.materials == EVEN.materials
    assert supply.get() is first  # kept: not read again
    # The file replaced (a rebuild, a library import writes a new one): the next get reads it.
    ODD.save(path)
    st = path.stat()
    os.utime(path, ns=(st.st_atime_ns, st.st_mtime_ns + 10**9))
    assert supply.symmetry() == BasisSymmetry.of(ODD)
    second = supply.get()
    assert second is not first
    assert BasisSymmetry.of(second) == BasisSymmetry.of(ODD)


def test_the_default_basis_not_built_yet_is_unknown_and_not_built_to_look(
        monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    monkeypatch.setenv("GONIO_CACHE_DIR", str(tmp_path / "empty"))
    supply = BasisSupply()
    assert supply.symmetry() is None
    assert not default_basis_path().exists()


def test_the_arc_warning_is_recorded_once_per_job(tmp_path: Path) -> None:
    store = JobStore(tmp_path / "jobs.sqlite")
    supply = BasisSupply(lambda: ODD)
    job = store.create_job(kind=HALF.kind, specimen="s", plan=HALF.model_dump(mode="json"),
                           rig={}).id
    odd = BasisSymmetry.of(ODD)
    assert supply.note_arc(store, job, HALF, None) is None  # basis unknown: nothing said
    first = supply.note_arc(store, job, HALF, odd)
    assert first is not None and "span_deg 360" in first
    assert supply.note_arc(store, job, HALF, odd) == first  # said again to the caller ...
    # ... and by another process on the same store: recorded once all the same.
    assert BasisSupply(lambda: ODD).note_arc(store, job, HALF, odd) == first
    events = [e for e in store.events_after(0, job_id=job) if e.type == "arc_warning"]
    assert len(events) == 1 and events[0].data["message"] == first
    assert events[0].data["span_deg"] == 180
    full = store.create_job(kind=FULL.kind, specimen="s", plan=FULL.model_dump(mode="json"),
                            rig={}).id
    assert supply.note_arc(store, full, FULL, odd) is None
    assert supply.note_arc(store, job, HALF, BasisSymmetry.of(EVEN)) is None
    assert not store.has_event(full, "arc_warning")


def test_the_asymmetric_basis_is_asked_for_once_and_only_when_wanted() -> None:
    calls: list[int] = []

    def odd() -> Basis:
        calls.append(1)
        return ODD

    supply = BasisSupply(lambda: EVEN, odd)
    assert supply.has_asymmetric and not supply.asymmetric_build_needed()
    assert supply.asymmetric_build_s() is None and calls == []  # looked at, not asked
    assert supply.asymmetric() is ODD and supply.asymmetric() is ODD and calls == [1]
    own = BasisSupply(lambda: EVEN)  # a saved basis of its own, nothing beside it
    assert not own.has_asymmetric and own.asymmetric() is None


def test_the_default_asymmetric_basis_is_its_cache_file_and_its_build_is_announced(
        monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    monkeypatch.setenv("GONIO_CACHE_DIR", str(tmp_path / "cache"))
    supply = BasisSupply()
    assert supply.has_asymmetric and supply.asymmetric_build_needed()
    # Neither library is tabulated in this cache: the default one's build comes first.
    assert supply.asymmetric_build_s() == ASYMMETRIC_BASIS_BUILD_S + BASIS_BUILD_S
    text, fraction = supply.asymmetric_wait_report(30.0)
    assert "building" in text and "not twofold symmetric" in text and fraction is None
    assert f"{(ASYMMETRIC_BASIS_BUILD_S + BASIS_BUILD_S) / 60:.0f} minutes" in text
    path = default_basis_path(asymmetric=True)
    assert path != default_basis_path()
    path.parent.mkdir(parents=True, exist_ok=True)
    ODD.save(path)
    assert not supply.asymmetric_build_needed() and supply.asymmetric_build_s() is None
    assert "loading" in supply.asymmetric_wait_report(30.0)[0]
    got = supply.asymmetric()
    assert got is not None and got.K == ODD.K and not got.half_turn_periodic
    assert supply.asymmetric() is got  # kept while the file is unchanged
    assert not default_basis_path().exists()  # the default basis was not made to get it


def test_the_asymmetric_basis_is_prewarmed_once_in_a_thread_of_its_own() -> None:
    release = threading.Event()
    calls: list[str] = []

    def build() -> Basis:
        calls.append(threading.current_thread().name)
        release.wait(30)  # a build of minutes, held until the test lets it end
        return ODD

    supply = BasisSupply(lambda: EVEN, asymmetric_provider=build)
    assert not supply.asymmetric_prewarming
    assert supply.prewarm_asymmetric()
    assert not supply.prewarm_asymmetric()  # one build, however often a verdict asks
    assert supply.asymmetric_prewarming
    # Finishing's own call waits for the build in progress rather than starting another.
    got: list[Basis | None] = []
    waiter = threading.Thread(target=lambda: got.append(supply.asymmetric()))
    waiter.start()
    release.set()
    waiter.join(30)
    assert got == [ODD] and calls == ["gonio-asymmetric-basis"]
    # A supply with no such basis starts nothing.
    plain = BasisSupply(lambda: EVEN)
    assert not plain.prewarm_asymmetric() and not plain.asymmetric_prewarming
