import numpy as np
import pytest

from gmis.epochs import merge_streams
from gmis.errors import GmisInputError


def test_coincident_samples_share_an_epoch_and_others_get_their_own():
    imu_t = np.arange(0.0, 1.0, 0.01)
    pos_t = np.array([0.2, 0.4000004, 0.455])   # last one is between IMU epochs
    hdg_t = np.array([0.2, 0.455])
    ep = merge_streams(imu_t, pos_t=pos_t, vel_t=pos_t, heading_t=hdg_t, tolerance_s=1e-3)
    assert len(ep) == imu_t.size + 1
    assert np.all(np.diff(ep.t) > 0)
    k = np.nonzero(np.isclose(ep.t, 0.2))[0][0]
    assert ep.imu[k] == 20 and ep.pos[k] == 0 and ep.vel[k] == 0 and ep.heading[k] == 0
    k2 = np.nonzero(np.isclose(ep.t, 0.455))[0][0]
    assert ep.imu[k2] == -1 and ep.pos[k2] == 2 and ep.heading[k2] == 1
    assert ep.pos[ep.pos >= 0].tolist() == [0, 1, 2]
    assert (ep.imu >= 0).sum() == imu_t.size


def test_two_samples_on_one_imu_epoch_is_an_error():
    imu_t = np.arange(0.0, 1.0, 0.01)
    with pytest.raises(GmisInputError, match="pos"):
        merge_streams(imu_t, pos_t=np.array([0.2, 0.2002]), tolerance_s=1e-3)


def test_without_imu_every_aiding_sample_is_its_own_epoch():
    """The no-IMU tightly coupled run (gmis.tc_gnss_only) merges GNSS epochs only."""
    pos_t = np.array([0.0, 30.0, 60.0])
    ep = merge_streams(np.empty(0), pos_t=pos_t, heading_t=np.array([30.0]))
    assert ep.t.tolist() == pos_t.tolist()
    assert np.all(ep.imu == -1) and ep.pos.tolist() == [0, 1, 2]
    assert ep.heading.tolist() == [-1, 0, -1]
