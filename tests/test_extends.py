"""A preset that is another at a different size says so in data: ``extends`` lays its keys over the
other scene's."""

import dataclasses

import pytest

from pbf.scene import SceneError, load_scene


def test_the_large_dam_break_is_the_seed_scene_but_for_what_it_sets():
    seed, large = load_scene("dam_break"), load_scene("dam_break_large")
    assert large.fluid.spacing_m == 0.005 and large.time.substeps == 10 and large.particle_count == 1_000_000
    assert large.time.max_speed_m_s == 5.2  # the splash's fastest drops capped (docs/METHOD.md, "Time steps")
    assert large.solver.target_density_error == 0.004  # 100 particles deep (docs/BENCHMARKS.md)
    same = dataclasses.replace(
        large,
        name=seed.name,
        description=seed.description,
        source=seed.source,
        fluid=dataclasses.replace(large.fluid, spacing_m=seed.fluid.spacing_m),
        time=dataclasses.replace(large.time, substeps=seed.time.substeps, max_speed_m_s=seed.time.max_speed_m_s),
        solver=dataclasses.replace(large.solver, target_density_error=seed.solver.target_density_error),
        render=dataclasses.replace(large.render, width_px=1280, height_px=720),
    )
    assert same == seed
    # Its time step is the seed's scaled with the spacing.
    assert large.dt_s / seed.dt_s == pytest.approx(large.fluid.spacing_m / seed.fluid.spacing_m)


def test_tables_merge_and_lists_are_replaced(tmp_path):
    child = tmp_path / "child.toml"
    child.write_text(
        'extends = "dam_break"\n[solver]\niterations = 4\n'
        "[[fluid.blocks]]\nmin_m = [0.0, 0.0, 0.0]\nmax_m = [0.2, 0.2, 0.2]\n"
    )
    scene = load_scene(child)
    assert scene.solver.iterations == 4 and scene.solver.surface_density  # merged into the seed's
    assert len(scene.fluid.blocks) == 1 and scene.fluid.blocks[0].max_m == (0.2, 0.2, 0.2)
    grandchild = tmp_path / "grandchild.toml"
    grandchild.write_text('extends = "child.toml"\n[time]\nsubsteps = 3\n')
    assert load_scene(grandchild).solver.iterations == 4


def test_bad_extends_are_refused_naming_the_file(tmp_path):
    loop_a, loop_b = tmp_path / "a.toml", tmp_path / "b.toml"
    loop_a.write_text('extends = "b.toml"\n')
    loop_b.write_text('extends = "a.toml"\n')
    with pytest.raises(SceneError, match=r"b.toml: key 'extends': 'a.toml' extends this scene in turn"):
        load_scene(loop_a)
    missing = tmp_path / "missing.toml"
    missing.write_text('extends = "dam_brek"\n')
    with pytest.raises(SceneError, match=r"missing.toml: key 'extends': .*did you mean dam_break"):
        load_scene(missing)
    number = tmp_path / "number.toml"
    number.write_text("extends = 3\n")
    with pytest.raises(SceneError, match=r"number.toml: key 'extends': expected a preset name"):
        load_scene(number)
