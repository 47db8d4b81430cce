"""The result-file variables of the quality-engineering figures (issue 6): fraction out of
spec and capability of epsilon (:mod:`tolsim.study.statistics.quality`)."""

from tolsim.io.schema.declaration import Section
from tolsim.study.statistics.quality import dataset_quality

#: Declarations of the result-file variables of this module (name -> (units, long_name)),
#: for :mod:`tolsim.io.schema`; all scalars.
QUALITY_VARIABLES = {
    "velocity_deviation_out_of_spec_fraction": (
        "1", "fraction of valid balls with |epsilon| above the limit"),
    "velocity_deviation_out_of_spec_ci_lower": (
        "1", "lower end of the 95 % interval of the fraction out of spec, assemblies as the "
             "sampling unit"),
    "velocity_deviation_out_of_spec_ci_upper": (
        "1", "upper end of the 95 % interval of the fraction out of spec, assemblies as the "
             "sampling unit"),
    "velocity_deviation_cp": ("1", "process potential Cp = L / (3 sigma) of epsilon"),
    "velocity_deviation_cpk": ("1", "process capability Cpk = (L - |mu|) / (3 sigma) of "
                                    "epsilon"),
    "velocity_deviation_cpk_ci_lower": ("1", "lower end of the 95 % interval of Cpk, delta "
                                             "method over assemblies"),
    "velocity_deviation_cpk_ci_upper": ("1", "upper end of the 95 % interval of Cpk, delta "
                                             "method over assemblies"),
    "velocity_deviation_cpk_percentile": (
        "1", "percentile (ISO 22514-2) capability index of epsilon"),
}


def assign(result, ds):
    """The quality variables, computed from the Dataset's own histogram and moments."""
    quality = {k: v for k, v in dataset_quality(ds).items() if not k.startswith("_")}
    return ds.assign({name: float(value) for name, value in quality.items()})


SECTION = Section(assign=assign)
