#!/usr/bin/env bash
# Run the no-master unit tests on Python 3.8 with py_trees 2.2.x (the ROS Noetic platform),
# where a 3.8 interpreter is installed (python3.8 on PATH, or pyenv). Debian's ROS 1 Python
# packages are pure Python; a .pth file exposes just those to the 3.8 environment.
set -euo pipefail
cd "$(dirname "$0")/.."

py38=""
for c in python3.8 "$HOME"/.pyenv/versions/3.8*/bin/python3.8; do
  if command -v "$c" >/dev/null 2>&1 && "$c" -c 'import sys; assert sys.version_info[:2] == (3, 8)' 2>/dev/null; then
    py38=$(command -v "$c"); break
  fi
done
if [ -z "$py38" ]; then
  echo "py38: no Python 3.8 interpreter here; the static 3.8 checks (ruff py38, vermin) ran instead"
  exit 0
fi

V=.venv38
if [ ! -x "$V/bin/python" ]; then
  echo "py38: creating $V with $py38"
  "$py38" -m venv "$V"
fi
stamp=$V/.bmtree-installed
if [ ! -f "$stamp" ] || [ setup.py -nt "$stamp" ] || [ scripts/test-py38.sh -nt "$stamp" ]; then
  echo "py38: installing py_trees 2.2.x and the test dependencies"
  # the package's own requirements (setup.py), py_trees held at the oldest supported 2.2.x
  "$V/bin/python" -m pip install -q --disable-pip-version-check "py_trees>=2.2,<2.3" -e . \
    pytest pytest-xdist rospkg catkin_pkg defusedxml 2>&1 | grep -v "^WARNING: Location" || true
  touch "$stamp"
fi
site=$("$V/bin/python" -c 'import site; print(site.getsitepackages()[0])')
ros="$PWD/$V/ros"
mkdir -p "$ros"
rosdir=$(/usr/bin/python3 -c 'import os, genpy; print(os.path.dirname(os.path.dirname(genpy.__file__)))')
for p in catkin genmsg genpy roscpp rosgraph rosgraph_msgs roslaunch rosmaster rosclean roslib rospy std_msgs std_srvs geometry_msgs sensor_msgs actionlib actionlib_msgs move_base_msgs; do
  if [ -e "$rosdir/$p" ]; then ln -sfn "$rosdir/$p" "$ros/$p"; fi
done
echo "$ros" > "$site/bmtree-ros.pth"
"$V/bin/python" -c 'import sys, py_trees.version as v; print("py38: Python %s, py_trees %s" % (sys.version.split()[0], v.__version__))'
# on both cores, as the Python 3.11 suite (TEST_WORKERS=0: serially)
workers=${TEST_WORKERS:-2}
if [ "$workers" = 0 ]; then
  exec "$V/bin/python" -m pytest -q -p no:cacheprovider tests/unit
fi
exec "$V/bin/python" -m pytest -q -p no:cacheprovider -n "$(( workers < 2 ? workers : 2 ))" tests/unit
