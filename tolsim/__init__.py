"""tolsim: Monte Carlo tolerance analysis of ball-to-ball contact in linear ball bearings.

Layers, importing one way only (lower never imports higher)::

    tolsim.physics   pure kernels: Hertz contact, analytical velocity models,
                     static contact, full friction model        (numpy, scipy, numba)
    tolsim.study     sampling, evaluation and propagation       (+ physics)
    tolsim.io        TOML config, netCDF schema and writer      (+ study, xarray, tomllib)
    tolsim.reports   figures and reports                        (+ io, matplotlib)
    tolsim.cli       the ``tolsim`` command                     (+ everything)

Nomenclature (paper symbol -> code name), contacts always ordered BL, BR, TR, TL:

    R_B     ball_radius [m]             f       conformity [-] (groove radius = 2 f R_B)
    beta_i  contact_angle [rad]         beta_0  nominal_contact_angle [rad]
    dbeta_i contact_angle_deviation     F_i     normal_force [N]
    dgamma_i zero_velocity_offset [rad] (angular offset of the zero-velocity point)
    a_i,b_i semi_major / semi_minor [m] (a across the groove, b along the rail)
    epsilon velocity_deviation [-]      v_B = (1 + epsilon) v / 2
    v       groove_velocity [m/s]       mu      friction_coefficient [-]
    rho     side_force_ratio N_x/N_y    theta   groove rotation [rad]

Python API (what ``tolsim run`` does, usable in a notebook)::

    import tolsim
    config = tolsim.load_config()                  # the packaged default study, or a path
    result = tolsim.run_study(config.with_overrides(samples=20_000))
    tolsim.write_result(result, "study.nc")        # the CF-netCDF file of ``tolsim run``
    tolsim.analytic(dbeta, force)                  # epsilon of balls from their contact state

See ``API`` for every name and README.md (``## Python API``) for a worked example.

Reference: B. Lin, C. E. Okwudire, M. Duan, J. S. Wou, "An improved analytical model of
friction and ball motion in linear ball bearings - with application to ball-to-ball contact
prediction", IMECE2018-88033 (called "the paper" or [Lin2018] throughout).
"""

from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("tolsim")
except PackageNotFoundError:  # running from a source tree that is not installed
    __version__ = "0.0.0+unknown"

#: The Python API: name -> module. Imported on first use (PEP 562), so ``import tolsim`` stays
#: light (no Numba compilation, no xarray) and the ``tolsim`` command starts fast.
API = {
    # studies
    "load_config": "tolsim.io.config",
    "parse_config": "tolsim.io.config",
    "with_study_settings": "tolsim.io.config",
    "run_study": "tolsim.study.execution.runner",
    "write_result": "tolsim.io.netcdf",
    "read_result": "tolsim.io.netcdf",
    "linear_stackup": "tolsim.study.analyses.worst_case",
    "compare_runs": "tolsim.reports.compare",
    "solve_config_carriage": "tolsim.study.pipeline.carriage",
    "solve_carriage": "tolsim.physics.carriage",
    "solve_carriage_batch": "tolsim.physics.carriage",
    "CarriageLayout": "tolsim.physics.carriage",
    "CarriageLoad": "tolsim.physics.carriage",
    # physics: the velocity models, the static contact, the bearing
    "eq24": "tolsim.physics.velocity.analytic",
    "analytic": "tolsim.physics.velocity.analytic",
    "point": "tolsim.physics.velocity.analytic",
    "full": "tolsim.physics.velocity.full",
    "solve_static": "tolsim.physics.static",
    "GrooveErrors": "tolsim.physics.static",
    "paired_forces": "tolsim.physics.geometry",
    "Bearing": "tolsim.physics.geometry",
    "TABLE1": "tolsim.physics.geometry",
}

__all__ = ["__version__", *API]


def __getattr__(name):
    module = API.get(name)
    if module is None:
        raise AttributeError(f"module 'tolsim' has no attribute {name!r}")
    import importlib  # noqa: PLC0415

    value = getattr(importlib.import_module(module), name)
    globals()[name] = value  # later look-ups skip this function
    return value


def __dir__():
    return sorted(set(globals()) | set(API))
