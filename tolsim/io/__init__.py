"""I/O layer: the TOML study config (:mod:`~tolsim.io.config`), the declared netCDF schema
(:mod:`~tolsim.io.schema`), the result writer/reader (:mod:`~tolsim.io.netcdf`) with the
SHA-256 checksums of its variables (:mod:`~tolsim.io.checksums`) and a what-if sweep's run
into one result file (:mod:`~tolsim.io.sweep`).

Typical use, without the command line::

    from tolsim.io.config import load_config
    from tolsim.io.netcdf import write_result
    from tolsim.study.execution.runner import run_study

    result = run_study(load_config("configs/yaw_moment_tolerances.toml"))
    write_result(result, "yaw.nc")
"""
