"""Small scenes the tests share, as dicts shaped like the TOML files."""


def column_scene(spacing_m=0.025, substeps=4, iterations=4, height_m=0.4, **solver):
    """A tank 0.3 m square filled to ``height_m`` with water at rest; Δt = 1/60 s / substeps."""
    return {
        "name": "column",
        "container": {"min_m": [0.0, 0.0, 0.0], "max_m": [0.3, 0.6, 0.3]},
        "fluid": {"spacing_m": spacing_m, "blocks": [{"min_m": [0.0, 0.0, 0.0], "max_m": [0.3, height_m, 0.3]}]},
        "time": {"substeps": substeps},
        "solver": {"iterations": iterations, **solver},
    }


def small_dam_break(iterations=4, substeps=2):
    """A coarse dam break (1,728 particles) for tests that need motion."""
    return {
        "name": "small_dam_break",
        "container": {"min_m": [0.0, 0.0, 0.0], "max_m": [0.8, 0.8, 0.4]},
        "fluid": {"spacing_m": 0.033333, "blocks": [{"min_m": [0.0, 0.0, 0.0], "max_m": [0.4, 0.4, 0.4]}]},
        "time": {"substeps": substeps},
        "solver": {"iterations": iterations},
    }
