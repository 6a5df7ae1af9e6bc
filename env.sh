# Source this file to use objslam from a shell: `source env.sh` (after `make setup`).
# It activates .venv (rclpy, GTSAM, the `objslam` command) and the colcon workspace
# (objslam_msgs, and `ros2 run`-style install/ layout).
_objslam_root="$(cd "$(dirname "${BASH_SOURCE[0]:-$0}")" && pwd)"
# shellcheck disable=SC1091
source "$_objslam_root/.venv/bin/activate"
# shellcheck disable=SC1091
source "$_objslam_root/install/setup.bash"
unset _objslam_root
