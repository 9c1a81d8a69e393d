"""Generate a large, valid IDL file for the front-end benchmark.

`python bench/gen_idl.py N > big.idl` writes N modules (default 200, about 9,000 lines), each with
structs, typedefs, constants, an enum, a union, an exception and an interface that uses types of
the previous module, so that name resolution crosses scopes as in real robot IDL.
"""

from __future__ import annotations

import sys


def module(i: int) -> str:
    prev = f"M{i - 1}::" if i > 0 else ""
    use_prev = f"    {prev}Pose prev_pose;\n" if i > 0 else ""
    return f"""\
/// Module number {i}: sensors and their interfaces.
module M{i} {{
  const long SIZE = {i % 50 + 1};
  const unsigned long long MASK = (1 << {i % 60}) | 0x{i:x};
  const double SCALE = {i}.5 * 2.0;
  const string NAME = "module {i}";
  enum Mode {{ IDLE, RUNNING, STOPPED, FAULT }};
  /** A pose in the plane. */
  struct Pose {{
    double x;
    double y;
    double theta;
  }};
  typedef sequence<Pose> PoseSeq;
  typedef sequence<Pose, SIZE> BoundedPoseSeq;
  typedef double Matrix[3][3];
  typedef string<32> Label;
  struct Reading {{
    unsigned long long stamp;
    Mode current_mode;
    PoseSeq path;
    Matrix covariance;
    Label tag;
    sequence<octet> raw;
    float values[SIZE];
{use_prev}  }};
  union Value switch (Mode) {{
    case IDLE: long code;
    case RUNNING: Pose where;
    case STOPPED: case FAULT: string reason;
  }};
  exception Failure {{ string what; long code; }};
  interface Sensor {{
    readonly attribute Label sensor_name;
    attribute Mode operating_mode;
    Reading latest() raises (Failure);
    Reading wait_next(in unsigned long timeout_ms) raises (Failure);
    void configure(in PoseSeq poses, inout Value setting, out long status);
    oneway void ping();
  }};
  interface Fusion : Sensor {{
    PoseSeq fused(in BoundedPoseSeq input, in double weight);
  }};
}};

"""


def main() -> None:
    n = int(sys.argv[1]) if len(sys.argv) > 1 else 200
    text = "".join(module(i) for i in range(n))
    sys.stdout.write(text)


if __name__ == "__main__":
    main()
