"""The sun-path benchmark's hotspot block: rendered frames measured by the loop's estimator."""

import numpy as np

from benchmarks.sunpath import ANDIMESHK, make_dataset
from benchmarks.sunpath_hotspot import hotspot_dataset, sensor_errors


def test_hotspot_dataset_observes_clear_frames_and_loses_clouded_ones():
    ds = make_dataset(ANDIMESHK, 3.5, dates=("2024-03-27",), clouds_per_day=0.0)
    keep = np.zeros(ds.t.size, bool)
    keep[[4, 12, 20, 28]] = True  # 09:00, 11:00, 13:00, 15:00 local
    ds.t, ds.az_true, ds.el_true = ds.t[keep], ds.az_true[keep], ds.el_true[keep]
    ds.az_obs, ds.el_obs = ds.az_obs[keep], ds.el_obs[keep]
    ds.clear = np.array([True, True, False, True])  # a thick cloud over the 13:00 frame
    hds, reasons = hotspot_dataset(ds, workers=1)
    assert hds.clear.tolist() == [True, True, False, True]
    assert reasons == {"cloud: no_glint": 1}
    assert hds.sensor == "hotspot" and np.all(hds.sigma[hds.clear] < 0.5)
    err = sensor_errors(hds)
    assert err["n"] == 3 and err["max_deg"] < 0.2  # the recommended camera: ~0.02 deg RMS
    obs = hds.observations()
    assert [o.time for o in obs] == list(ds.t[[0, 1, 3]])
    assert all(o.sensor == "hotspot" for o in obs)
