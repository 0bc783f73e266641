"""Run inside a Python environment that has mobgap (not pdr's): mobgap's SlZijlstra on the Mobilise-D TVS lab data
with the INDIP reference initial contacts of each walking bout; prints one JSON list (one item per bout).

Usage: ``PEER_PYTHON benchmarks/peers/mobgap_stride_length.py DATASET_LAB_FOLDER`` (called by ``bench_peer``).
Per bout: the mean of ``stride_length_per_sec_``; ``bench_peer`` turns it into a distance with the reference's rule,
mean stride / 2 x (n_initial_contacts - 1), as for pdr's reference-IC rows in ``bench_step_length``.
"""

import json
import sys
import warnings
from pathlib import Path

warnings.simplefilter("ignore")

from mobgap.data import GenericMobilisedDataset  # noqa: E402
from mobgap.stride_length import SlZijlstra  # noqa: E402
from mobgap.utils.conversions import to_body_frame  # noqa: E402


def main(lab: Path) -> None:
    paths = sorted(lab.rglob("data.mat"))
    ds = GenericMobilisedDataset(paths, GenericMobilisedDataset.COMMON_TEST_LEVEL_NAMES["tvs_lab"],
                                 ["cohort", "participant_id"], measurement_condition="laboratory",
                                 reference_system="INDIP", reference_para_level="wb")
    out = []
    for dp in ds:
        meta = dp.group_label
        fs = float(dp.sampling_rate_hz)
        try:
            ref = dp.reference_parameters_relative_to_wb_
        except Exception:  # no INDIP bout in this trial
            continue
        data = dp.data_ss
        height = float(dp.participant_metadata["sensor_height_m"])
        for wb_id, wb in ref.wb_list.iterrows():
            ics = ref.ic_list.loc[wb_id][["ic"]].reset_index(drop=True)
            segment = to_body_frame(data.iloc[int(wb["start"]): int(wb["end"])])
            for name, params in (("ms_all", SlZijlstra.PredefinedParameters.step_length_scaling_factor_ms_all),
                                 ("ms_ms", SlZijlstra.PredefinedParameters.step_length_scaling_factor_ms_ms)):
                sl = SlZijlstra(**params).calculate(segment, ics, sampling_rate_hz=fs, sensor_height_m=height)
                stride = float(sl.stride_length_per_sec_["stride_length_m"].mean())
                out.append({"participant": meta.participant_id, "test": meta.test, "trial": meta.trial,
                            "t_start_s": int(wb["start"]) / fs, "t_end_s": int(wb["end"]) / fs,
                            "n_ic": int(len(ics)), "factor": name, "mean_stride_m": stride})
    print(json.dumps(out))


if __name__ == "__main__":
    main(Path(sys.argv[1]))
