"""The plant driven by recorded voltages, compiled (apart: the fit's module compiles nothing)."""
from gripper_ros.core.physics.plant import PLANT_DTYPE, plant_read_tick, plant_step
from gripper_ros.core.records import face_kernel, FLOATS, FLOATS_2D, INTS
from gripper_ros.wire import TICK_LAYOUT
import numba


@face_kernel(PLANT_DTYPE, INTS, FLOATS, FLOATS_2D, TICK_LAYOUT.dtype)
@numba.njit(cache=True)
def run_plant(k, t_ns, voltage_v, out, tick):
    """Drive the plant ``k`` with the recorded voltages; fill out[n] = (x, w, i, F)."""
    for n in range(t_ns.shape[0]):
        if n > 0:
            plant_step(k, voltage_v[n], t_ns[n] - t_ns[n - 1])
        plant_read_tick(k, tick, 0, 0)
        t = tick[0]
        out[n, 0] = t.position_m
        out[n, 1] = t.speed_rad_s
        out[n, 2] = t.current_a
        out[n, 3] = t.force_n
