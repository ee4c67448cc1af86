#!/usr/bin/env bash
# Idempotent set-up: ROS 1 from Debian (skipped where rospy already imports, e.g. a
# sourced Noetic), graphviz, a .venv with system site packages, and bmtree in it.
set -euo pipefail
cd "$(dirname "$0")/.."

ROS_DEBS="python3-rospy python3-rosmaster python3-roslaunch python3-rostopic python3-std-msgs \
python3-geometry-msgs python3-sensor-msgs python3-std-srvs python3-genpy"
SUDO=""
if [ "$(id -u)" != 0 ]; then SUDO="sudo"; fi

need=()
if ! /usr/bin/python3 -c 'import rospy, genpy, std_msgs.msg, geometry_msgs.msg, sensor_msgs.msg, std_srvs.srv' 2>/dev/null \
   || ! command -v rosmaster >/dev/null; then
  need+=($ROS_DEBS)
fi
command -v dot >/dev/null || need+=(graphviz)
/usr/bin/python3 -c 'import ensurepip, venv' 2>/dev/null || need+=(python3-venv)
if [ ${#need[@]} -gt 0 ]; then
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
