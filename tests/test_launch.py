"""The substep's kernels launched past Taichi's per-call Python (``pbf.solver.launch.Launcher``) run as
ordinary calls do: the variant the template arguments select, the arguments of this call, the same bits.
Only on the Taichi the launch was written for, and not under ``PBF_PUBLIC_LAUNCH=1``: elsewhere every
call is Taichi's own. Arguments by name as by position; what the studies see of the launches."""

from pathlib import Path

import numpy as np
import pytest
import taichi as ti

from benchmarks.instruments import Observer, watching, watching_nothing
from pbf.solver import Simulation, launch
from pbf.solver.backend import choices
from pbf.solver.launch import PUBLIC_LAUNCH_VAR, Launcher, knows_taichi
from tests.scenes import small_dam_break


@pytest.fixture(autouse=True)
def fast(monkeypatch):
    """The fast launch on for each test here, whatever the environment says (CI runs the suite with it
    off too): these tests are about it. A test of the gate turns it off again."""
    if not knows_taichi():
        pytest.skip(f"the fast launch reads Taichi {launch.WRITTEN_FOR}'s internals; this is {ti.__version__}")
    monkeypatch.delenv(PUBLIC_LAUNCH_VAR, raising=False)


@ti.data_oriented
class Writer:
    def __init__(self):
        self.out = ti.field(ti.f32, shape=4)
        self.other = ti.field(ti.f32, shape=4)

    @ti.kernel
    def write(self, target: ti.template(), doubled: ti.template(), value: ti.f32, scale: ti.i32) -> ti.f32:
        for i in range(4):
            v = value * scale + i
            if ti.static(doubled):
                v *= 2.0
            target[i] = v
        return value * scale

    @ti.kernel
    def add(self, values: ti.types.ndarray(dtype=ti.f32, ndim=1)):
        for i in range(4):
            self.out[i] += values[i]

    @ti.kernel
    def mix(self, target: ti.template(), value: ti.f32, scale: ti.i32, count: ti.u32, values: ti.types.ndarray()):
        for i in range(4):
            target[i] = value * scale + ti.cast(count, ti.f32) + values[i]


def test_each_call_launches_the_variant_its_template_arguments_select_with_its_own_arguments():
    writer = Writer()
    call = Launcher(writer.write)
    compiled = writer.write._primal.compiled_kernels
    before = len(compiled)
    for value, doubled, target in [(1.0, False, "out"), (2.0, True, "out"), (3.0, False, "other"), (4.0, False, "out")]:
        returned = call(getattr(writer, target), doubled, value, 3)
        assert returned == value * 3
        expected = (value * 3 + np.arange(4)) * (2.0 if doubled else 1.0)
        np.testing.assert_array_equal(getattr(writer, target).to_numpy(), expected.astype(np.float32))
    # Three variants (out, plain), (out, doubled), (other, plain), each compiled once, by Taichi's own call.
    assert len(compiled) - before == 3
    assert len(call._variants) == 3
    assert call._primal is not None  # this Taichi has what the direct launch reads


def test_a_new_array_of_the_same_kind_is_the_one_launched_with():
    writer = Writer()
    call = Launcher(writer.add)
    call(ti.ndarray(ti.f32, 4))  # zeros: the first call, through Taichi's own path
    for k in range(1, 4):
        values = ti.ndarray(ti.f32, 4)
        values.from_numpy(np.full(4, k, np.float32))
        call(values)
    np.testing.assert_array_equal(writer.out.to_numpy(), np.full(4, 1.0 + 2.0 + 3.0, np.float32))
    assert len(call._variants) == 1


def test_a_kernel_without_results_is_launched_from_its_arguments_set_as_taichi_sets_them():
    # Float, signed, unsigned and array arguments set straight into the launch context, the compiled
    # code looked up once: the same values as Taichi's own call, every call with its own arguments.
    writer = Writer()
    call = Launcher(writer.mix)
    values = ti.ndarray(ti.f32, 4)
    values.from_numpy(np.arange(4, dtype=np.float32))
    for value, scale, count in [(1.5, 2, 3), (-0.25, -3, 4_000_000_000), (np.float32(2.0), np.int64(5), 0)]:
        call(writer.out, value, scale, count, values)
        expected = np.float32(value) * scale + np.float32(count) + np.arange(4, dtype=np.float32)
        np.testing.assert_array_equal(writer.out.to_numpy(), expected.astype(np.float32))
    (entry,) = call._variants.values()
    assert entry[2] is not None  # launched from the context, past Kernel.launch_kernel


def test_an_argument_taichi_refuses_is_refused_in_taichis_words():
    writer = Writer()
    call = Launcher(writer.mix)
    values = ti.ndarray(ti.f32, 4)
    call(writer.out, 1.0, 1, 1, values)
    for bad in [
        (writer.out, "1.0", 1, 1, values),
        (writer.out, 1.0, 1.5, 1, values),
        (writer.out, 1.0, 1, 1, [0.0]),
        (writer.out, 1.0, 1, 1, values, 2.0),
    ]:
        with pytest.raises(Exception) as direct:
            call(*bad)
        with pytest.raises(Exception) as ordinary:
            writer.mix(*bad)
        assert type(direct.value) is type(ordinary.value) and str(direct.value).strip() == str(ordinary.value).strip()
    np.testing.assert_array_equal(writer.out.to_numpy(), np.full(4, 2.0, np.float32))  # nothing launched


def test_fields_allocated_after_a_launch_are_there_for_the_next():
    writer = Writer()
    call = Launcher(writer.write)
    call(writer.out, False, 1.0, 1)
    later = Writer()  # new fields, placed after the kernel was compiled and launched
    call(writer.out, False, 5.0, 1)
    later.out[0] = 7.0  # the new fields are usable
    assert later.out[0] == 7.0
    np.testing.assert_array_equal(writer.out.to_numpy(), 5.0 + np.arange(4, dtype=np.float32))


def test_what_is_not_a_bound_kernel_is_called_as_it_is():
    calls = []
    call = Launcher(lambda *args: calls.append(args) or len(calls))
    assert call(1, 2) == 1 and call(3) == 2
    assert calls == [(1, 2), (3,)]


def launchers(sim) -> list[Launcher]:
    """The Launchers of a Simulation's substep."""
    owners = (sim, sim.kernels)
    return [value for owner in owners for value in vars(owner).values() if isinstance(value, Launcher)]


@pytest.mark.parametrize(
    "on_device", [pytest.param(False, id="cpu path"), pytest.param(True, id="device path", marks=pytest.mark.slow)]
)
def test_the_substep_launched_directly_steps_the_bits_of_ordinary_calls(on_device):
    # One Simulation run twice from its start (reset() restores it exactly): launched directly, then
    # with every Launcher calling its kernel the ordinary way. One set of kernels, not two.
    sim = Simulation(small_dam_break(), quiet=True, choices=choices(decisions_on_device=on_device))
    assert len(launchers(sim)) == 3  # lines 1-7, the divergence pass's further iterations, the iterations
    start = sim.positions()
    sim.step(10)
    assert sum(len(launcher._variants) for launcher in launchers(sim)) >= 3  # launched directly
    # The three kernels return nothing: launched from their contexts.
    if True:
        assert sum(entry[2] is not None for launcher in launchers(sim) for entry in launcher._variants.values()) >= 3
    direct = sim.positions(), sim.velocities()
    assert np.abs(direct[0] - start).max() > 0.05  # the splash began
    sim.reset()
    for launcher in launchers(sim):
        launcher._primal = None  # each call the ordinary way
    sim.step(10)
    np.testing.assert_array_equal(direct[0], sim.positions())
    np.testing.assert_array_equal(direct[1], sim.velocities())


def test_a_template_argument_equal_to_nothing_is_not_kept_without_end(monkeypatch):
    writer = Writer()
    call = Launcher(writer.write)
    for _ in range(3):
        call(writer.out, float("nan"), 1.0, 1)  # a float template argument: NaN is not equal to itself
    assert len(call._variants) <= 3
    monkeypatch.setattr(launch, "MOST_VARIANTS", 4)
    for value in range(6):  # a new variant each call (a flag of other values): kept up to the most
        call(writer.out, value, 1.0, 1)
    assert len(call._variants) == 4
    np.testing.assert_array_equal(writer.out.to_numpy(), 2.0 * (1.0 + np.arange(4, dtype=np.float32)))


class Seen(Observer):
    """Every launch and compile an observer is told of."""

    def __init__(self):
        self.launches, self.waits, self.compiles, self.accesses = [], 0, [], []

    def launched(self, kernel, waits):
        self.launches.append(kernel)
        self.waits += waits

    def accessed(self, read):
        self.accesses.append(read)

    def compiled(self, kernel, seconds):
        assert seconds > 0
        self.compiles.append(kernel)


def counting_up():
    """An ndarray of 0, 1, 2, 3."""
    values = ti.ndarray(ti.f32, 4)
    values.from_numpy(np.arange(4, dtype=np.float32))
    return values


@pytest.mark.parametrize("switch", ["1", "yes"])
def test_the_environment_switch_takes_taichis_public_call(monkeypatch, switch):
    monkeypatch.setenv(PUBLIC_LAUNCH_VAR, switch)
    assert not launch.fast_launch()
    writer = Writer()
    call = Launcher(writer.write)
    for value in (1.0, 2.0, 3.0):
        assert call(writer.out, False, value, 3) == value * 3
    np.testing.assert_array_equal(writer.out.to_numpy(), 9.0 + np.arange(4, dtype=np.float32))
    assert call._primal is None and not call._variants  # nothing kept: every call Taichi's own


def test_another_taichi_version_takes_taichis_public_call(monkeypatch):
    # Another build with the same public API may lay out its internals otherwise: the gate is the
    # version, not whether the names exist (they do here).
    monkeypatch.setattr(ti, "__version__", (1, 7, 5))
    assert not launch.knows_taichi() and not launch.fast_launch()
    writer = Writer()
    call = Launcher(writer.mix)
    values = counting_up()
    for value in (1.0, 2.0):
        call(writer.out, value, 2, 1, values)
    np.testing.assert_array_equal(writer.out.to_numpy(), 5.0 + np.arange(4, dtype=np.float32))
    assert call._primal is None and not call._variants
    with pytest.raises(RuntimeError, match="1.7.5"):  # the studies' hooks say why they cannot watch
        with watching(Seen()):
            pass


@pytest.mark.parametrize("fast_launch", [True, False], ids=["fast", "public"])
def test_arguments_by_name_land_where_their_names_say(monkeypatch, fast_launch):
    if not fast_launch:
        monkeypatch.setenv(PUBLIC_LAUNCH_VAR, "1")
    writer = Writer()
    call = Launcher(writer.mix)
    values = counting_up()
    calls = [
        ((writer.out, 1.5, 2, 3, values), {}),
        ((writer.out,), {"values": values, "count": 3, "scale": 2, "value": 1.5}),
        ((), {"target": writer.out, "value": 1.5, "scale": 2, "count": 3, "values": values}),
        ((writer.out, 1.5), {"count": 3, "scale": 2, "values": values}),
    ]
    for args, kwargs in calls * 2:  # each twice: the first call of the variant, then the direct launch
        writer.out.fill(0.0)
        call(*args, **kwargs)
        np.testing.assert_array_equal(writer.out.to_numpy(), 1.5 * 2 + 3.0 + np.arange(4, dtype=np.float32))
    # Two neighbouring values of one type, swapped by name: each where its name says.
    call(writer.out, 0.0, count=7, scale=1, values=values)
    np.testing.assert_array_equal(writer.out.to_numpy(), 7.0 + np.arange(4, dtype=np.float32))
    assert len(call._variants) == (1 if fast_launch else 0)


def test_a_name_taichi_refuses_is_refused_in_taichis_words():
    writer = Writer()
    call = Launcher(writer.mix)
    values = counting_up()
    call(writer.out, 1.0, 1, 1, values)  # the variant kept: what follows would be launched directly
    for args, kwargs in [
        ((writer.out, 1.0, 1, 1), {"wrong": values}),  # an unknown name
        ((writer.out, 1.0, 1, 1, values), {"value": 2.0}),  # a value twice
        ((writer.out, 1.0), {"scale": 1, "values": values}),  # one missing
    ]:
        with pytest.raises(Exception) as direct:
            call(*args, **kwargs)
        with pytest.raises(Exception) as ordinary:
            writer.mix(*args, **kwargs)
        assert type(direct.value) is type(ordinary.value) and str(direct.value).strip() == str(ordinary.value).strip()


@pytest.mark.parametrize("fast_launch", [True, False], ids=["fast", "public"])
def test_an_observer_sees_each_launch_and_each_compile_once(monkeypatch, fast_launch):
    # The studies count launches and time compiles through these: the same counts on either path.
    if not fast_launch:
        monkeypatch.setenv(PUBLIC_LAUNCH_VAR, "1")
    writer = Writer()
    mix, write = Launcher(writer.mix), Launcher(writer.write)
    values = counting_up()
    with watching(Seen()) as seen:
        for value in (1.0, 2.0, 3.0):
            mix(writer.out, value, 1, 1, values)  # launched from its context after the first
            write(writer.other, False, value, 1)  # returns a value: the host waits on it
        write(writer.other, True, 1.0, 1)  # another variant: compiled
        writer.out[0] = 1.0  # an element written from Python, then one read
        assert writer.out[0] == 1.0
    assert seen.launches.count("Writer.mix") == 3 and seen.launches.count("Writer.write") == 4
    assert seen.waits == 4
    assert seen.compiles.count("Writer.write") == 2 and seen.compiles.count("Writer.mix") == 1
    assert seen.accesses == [False, True]
    assert watching_nothing()  # Taichi's classes as they were


def test_a_compile_error_with_the_short_positions_still_shows_its_line_with_taichis_caret():
    # The front end's positions are short while it compiles (start_taichi installs them on this Taichi);
    # an error being raised gets Taichi's whole text, which points at the node.
    launch.short_positions()
    assert getattr(launch.ASTTransformerContext.get_pos_info, "short", False)

    @ti.kernel
    def wrong():
        for i in range(4):
            not_defined_anywhere[i] = 1.0  # noqa: F821 (the error the test wants)

    with pytest.raises(Exception) as error:
        wrong()
    source = Path(__file__).read_text(encoding="utf-8").splitlines()
    line = next(n for n, text in enumerate(source, 1) if "not_defined_anywhere[i] = 1.0" in text)
    message = str(error.value)
    assert f"line {line}" in message and "not_defined_anywhere" in message, message
    assert "^^^" in message, message  # the caret under the name: Taichi's own text
