#!/usr/bin/env bash
# Idempotent set-up: ROS 1 from Debian (skipped where rospy already imports, e.g. a
# sourced Noetic), graphviz, a .venv with system site packages, and bmtree in it.
set -euo pipefail
cd "$(dirname "$0")/.."

ROS_DEBS="python3-rospy python3-rosmaster python3-roslaunch python3-rostopic python3-std-msgs \
python3-geometry-msgs python3-sensor-msgs python3-std-srvs python3-genpy rosout"
SUDO=""
if [ "$(id -u)" != 0 ]; then SUDO="sudo"; fi

need=()
if ! /usr/bin/python3 -c 'import rospy, genpy, std_msgs.msg, geometry_msgs.msg, sensor_msgs.msg, std_srvs.srv' 2>/dev/null \
   || ! command -v rosmaster >/dev/null; then
  need+=($ROS_DEBS)
fi
# actionlib: modules/actions.py and its tests, and make bench's peer baseline (a MoveBase goal round trip)
BENCH_DEBS="python3-actionlib python3-actionlib-msgs python3-move-base-msgs"
if ! /usr/bin/python3 -c 'import actionlib, actionlib_msgs.msg, move_base_msgs.msg' 2>/dev/null \
   && apt-cache show python3-actionlib >/dev/null 2>&1; then
  need+=($BENCH_DEBS)
fi
command -v dot >/dev/null || need+=(graphviz)
# the catkin package and its tests: catkin_make, rosrun, and ss/ip for the network tests
command -v catkin_make >/dev/null || need+=(catkin)
command -v rosrun >/dev/null || need+=(rosbash)
command -v rosnode >/dev/null || need+=(python3-rosnode)   # rosnode kill / cleanup, which bmtree's messages name
[ -x /usr/lib/rosout/rosout ] || [ -n "${ROS_DISTRO:-}" ] || need+=(rosout)   # roslaunch starts it
{ command -v ss >/dev/null && command -v ip >/dev/null; } || need+=(iproute2)
# C++ basic modules (modules/cpp): a compiler, cmake, roscpp and the message headers, nlohmann json
command -v g++ >/dev/null || need+=(g++)
command -v cmake >/dev/null || need+=(cmake)
have_any() { for f in "$@"; do [ -e "$f" ] && return 0; done; return 1; }
if ! have_any /usr/lib/*/cmake/roscpp/roscppConfig.cmake /opt/ros/*/share/roscpp/cmake/roscppConfig.cmake \
   || ! have_any /usr/include/geometry_msgs/Point.h /opt/ros/*/include/geometry_msgs/Point.h; then
  need+=(libroscpp-dev libstd-msgs-dev libgeometry-msgs-dev catkin)
fi
[ -f /usr/include/nlohmann/json.hpp ] || need+=(nlohmann-json3-dev)
command -v tmux >/dev/null || need+=(tmux)                       # the terminal view's tests
command -v chromium >/dev/null || need+=(chromium)               # the web view's browser tests
command -v chromedriver >/dev/null || need+=(chromium-driver)
/usr/bin/python3 -c 'import ensurepip, venv' 2>/dev/null || need+=(python3-venv)
if [ ${#need[@]} -gt 0 ]; then
  mapfile -t need < <(printf '%s\n' "${need[@]}" | awk '!seen[$0]++')   # each once, in order
  echo "setup: installing Debian packages: ${need[*]}"
  $SUDO apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq "${need[@]}" >/dev/null
fi

if [ ! -x .venv/bin/python ]; then
  echo "setup: creating .venv"
  /usr/bin/python3 -m venv --system-site-packages .venv
  # Ubuntu 20.04's venv pip (20.0) predates editable installs of pyproject projects
  .venv/bin/python -m pip install -q --disable-pip-version-check --upgrade pip
fi
stamp=.venv/.bmtree-installed
if [ ! -f "$stamp" ] || [ setup.py -nt "$stamp" ] || [ pyproject.toml -nt "$stamp" ]; then
  echo "setup: pip install -e .[test]"
  .venv/bin/python -m pip install -q --disable-pip-version-check -e '.[test]'
  touch "$stamp"
fi
