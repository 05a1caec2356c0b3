"""The reference for the online generator's tests: Ruckig's own implementation (PyPI's
`ruckig`, the C++ library's Python binding), independent of the Rust port we ship.

Reads cases from standard input, one per line, numbers separated by spaces:
  dofs  p0[dofs] v0[dofs] a0[dofs] target[dofs] vmax[dofs] amax[dofs] jmax[dofs]  k  t[k]
and writes one line per case: the time-optimal, time-synchronised duration to the target at
rest, then each DoF's position at each of the k times (time-major), or `error <result>`.
"""

import sys

from ruckig import InputParameter, Result, Ruckig, Trajectory


def solve(numbers):
    dofs = int(numbers[0])
    values = [float(x) for x in numbers[1:]]
    take = lambda i: values[i * dofs:(i + 1) * dofs]
    inp = InputParameter(dofs)
    inp.current_position = take(0)
    inp.current_velocity = take(1)
    inp.current_acceleration = take(2)
    inp.target_position = take(3)
    inp.target_velocity = [0.0] * dofs
    inp.target_acceleration = [0.0] * dofs
    inp.max_velocity = take(4)
    inp.max_acceleration = take(5)
    inp.max_jerk = take(6)
    k = int(values[7 * dofs])
    times = values[7 * dofs + 1:7 * dofs + 1 + k]
    trajectory = Trajectory(dofs)
    result = Ruckig(dofs).calculate(inp, trajectory)
    if result not in (Result.Working, Result.Finished):
        return "error %s" % result
    out = [repr(trajectory.duration)]
    for t in times:
        position, _, _ = trajectory.at_time(t)
        out.extend(repr(p) for p in position)
    return " ".join(out)


for line in sys.stdin:
    if line.strip():
        print(solve(line.split()), flush=True)
