#!/usr/bin/env bash
# Start the uav_tilt node graph in namespace /uav, each node its own process (DESIGN §6).
#
# usage: scripts/launch.sh [--scenario F] [--realtime] [--record DIR] [--foxglove]
#          [--mission inspect | --mission plan --plan FILE] [--no-vision] [--target-source S]
#
# Lockstep unless --realtime. With --mission plan the controller runs the plan FILE, its site
# (the wall, the target ids) taken from the scenario as a survey would give it.
# Ctrl-C or SIGTERM sends SIGINT to every node (as ros2 launch
# does: every node shuts down cleanly on it); nodes still running after UAV_TILT_GRACE_S
# (5, whole) seconds are killed. Exit 0 only when every node stopped cleanly and,
# with --mission, the mission succeeded. Discovery is local-only unless
# ROS_AUTOMATIC_DISCOVERY_RANGE is set; ROS_DOMAIN_ID passes through.
# Executables come from .venv/bin, else PATH, else `python -m`.
set -euo pipefail

usage() { sed -n '4,5p' "${BASH_SOURCE[0]}" | sed 's/^# //'; }
log() { echo "[launch] $*" >&2; }
die() { log "$*"; usage >&2; exit 2; }

if ((BASH_VERSINFO[0] < 5 || (BASH_VERSINFO[0] == 5 && BASH_VERSINFO[1] < 1))); then
    echo "[launch] needs bash >= 5.1 (wait -n -p)" >&2
    exit 2
fi

REPO=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
CONFIG=$REPO/config
GRACE_S=${UAV_TILT_GRACE_S:-5}

scenario='' realtime=0 record='' mission='' plan='' foxglove=0 vision=1 target_source=''
while (($#)); do
    case $1 in
        --scenario) scenario=${2:-}; [[ -n $scenario ]] || die '--scenario needs a file'; shift 2 ;;
        --realtime) realtime=1; shift ;;
        --record) record=${2:-}; [[ -n $record ]] || die '--record needs a directory'; shift 2 ;;
        --mission)
            mission=${2:-}
            [[ $mission == inspect || $mission == plan ]] || die "--mission: 'inspect' or 'plan'"
            shift 2 ;;
        --plan) plan=${2:-}; [[ -n $plan ]] || die '--plan needs a file'; shift 2 ;;
        --foxglove) foxglove=1; shift ;;
        --no-vision) vision=0; shift ;;
        --target-source)
            target_source=${2:-}
            [[ $target_source == vision || $target_source == ground_truth ]] \
                || die '--target-source: vision or ground_truth'
            shift 2 ;;
        -h | --help) usage; exit 0 ;;
        *) die "unknown argument: $1" ;;
    esac
done

if [[ $mission == plan && -z $plan ]] || [[ -n $plan && $mission != plan ]]; then
    die '--mission plan and --plan FILE go together'
fi
[[ -z $plan || -f $plan ]] || die "--plan: no file $plan"
if ((!vision)) && [[ -n $mission && $target_source != ground_truth ]]; then
    log 'warning: with --no-vision the controller gets no target (--target-source ground_truth?)'
fi

export ROS_AUTOMATIC_DISCOVERY_RANGE=${ROS_AUTOMATIC_DISCOVERY_RANGE:-LOCALHOST}
export PYTHONUNBUFFERED=1

if [[ -x $REPO/.venv/bin/python ]]; then
    BIN=$REPO/.venv/bin
    PY=$BIN/python
else
    BIN=''
    PY=$(command -v python3) || die 'no .venv and no python3 on PATH'
fi

# CMD := the command of executable $1 (python module $2).
resolve() {
    if [[ -n $BIN && -x $BIN/$1 ]]; then
        CMD=("$BIN/$1")
    elif command -v "$1" >/dev/null; then
        CMD=("$(command -v "$1")")
    else
        CMD=("$PY" -m "$2")
    fi
}

# CMD += the ROS arguments of node $1 (its parameter file, if any) and use_sim_time.
ros_args() {
    CMD+=(--ros-args -r __ns:=/uav)
    [[ ! -f $CONFIG/$1.yaml ]] || CMD+=(--params-file "$CONFIG/$1.yaml")
    [[ $1 == plant ]] || CMD+=(-p use_sim_time:=true)
}

declare -A NAME_OF=() RUNNING=()
stop_signal=0
# Before the nodes run, a signal stops the start-up; from then on it starts the shutdown.
trap 'stop_signal=1' INT TERM
# Should this script fail, no node outlives it.
# shellcheck disable=SC2329  # invoked by the EXIT trap
kill_all() {
    local p
    for p in "${!RUNNING[@]}"; do kill -s KILL -- "-$p" 2>/dev/null || true; done
}
trap kill_all EXIT

start() {
    local name=$1
    ((!stop_signal)) || return 0
    # Job control gives each node its own process group, so a terminal's Ctrl-C reaches
    # the nodes once (from here), and their SIGINT is not ignored as in background jobs.
    set -m
    "${CMD[@]}" </dev/null &
    set +m
    NAME_OF[$!]=$name
    RUNNING[$!]=1
    log "$name (pid $!): ${CMD[*]}"
}

if [[ -n $record ]]; then
    mkdir -p "$record"
    resolve recorder_node uav_tilt_tools.recorder_node
    ros_args recorder
    CMD+=(-p "output:=$record")
    start recorder
fi
if [[ -n $mission ]]; then
    CMD=("$PY" -m uav_tilt_tools.mission_watch)
    ros_args mission_watch
    start mission_watch
fi
if ((foxglove)); then
    resolve foxglove_bridge uav_tilt_tools.foxglove_bridge
    ros_args foxglove
    [[ -z $scenario ]] || CMD+=(-p "scenario_file:=$scenario")
    start foxglove
fi
if ((vision)); then
    resolve vision_node uav_tilt_vision.vision_node
    ros_args vision
    start vision
fi
resolve controller_node uav_tilt_control.controller_node
ros_args controller
[[ -z $target_source ]] || CMD+=(-p "target_source:=$target_source")
[[ -z $mission ]] || CMD+=(-p "autostart:=$mission")
if [[ -n $plan ]]; then
    # the site the plan is checked against: the scenario's wall and target ids
    site=$("$PY" -m uav_tilt_tools.site_params "$scenario") || die 'bad scenario for the site'
    mapfile -t SITE <<<"$site"
    CMD+=(-p "plan_file:=$(realpath "$plan")" "${SITE[@]}")
fi
start controller
# The plant owns time: it starts last, so that its first ticks find the others listening.
resolve plant_node uav_tilt_sim.plant_node
ros_args plant
[[ -z $scenario ]] || CMD+=(-p "scenario_file:=$scenario")
if ((realtime)); then CMD+=(-p mode:=realtime); else CMD+=(-p mode:=lockstep); fi
start plant
log "ROS_DOMAIN_ID=${ROS_DOMAIN_ID:-0} ROS_AUTOMATIC_DISCOVERY_RANGE=$ROS_AUTOMATIC_DISCOVERY_RANGE"

failed=0
mission_code=''
declare -A CODE_OF=()
# Run until a signal, the end of the mission, or a node exits.
while ((!stop_signal && ${#RUNNING[@]})); do
    code=0
    unset pid
    wait -n -p pid "${!RUNNING[@]}" || code=$?
    # A trapped signal interrupts the wait and leaves pid unset.
    [[ -n ${pid:-} ]] || continue
    unset "RUNNING[$pid]"
    CODE_OF[$pid]=$code
    name=${NAME_OF[$pid]}
    if [[ $name == mission_watch ]]; then
        mission_code=$code
        log "mission ended (watcher exit code $code): stopping"
        break
    elif [[ $name == foxglove && $code == 0 ]]; then
        log 'foxglove bridge not running (see its log line); going on without it'
        continue
    fi
    log "$name (pid $pid) exited with code $code: stopping the others"
    failed=1
    break
done

# Shutdown: SIGINT to every node's process group, SIGKILL after the grace period.
for pid in "${!RUNNING[@]}"; do
    kill -s INT -- "-$pid" 2>/dev/null || true
done
for ((i = 0; i < GRACE_S * 10; i++)); do
    alive=0
    for pid in "${!RUNNING[@]}"; do
        if kill -0 "$pid" 2>/dev/null; then alive=1; fi
    done
    ((alive)) || break
    sleep 0.1
done
for pid in "${!RUNNING[@]}"; do
    if kill -0 "$pid" 2>/dev/null; then
        log "${NAME_OF[$pid]} (pid $pid) still running after ${GRACE_S} s: killing it"
        kill -s KILL -- "-$pid" 2>/dev/null || true
    fi
    code=0
    wait "$pid" || code=$?
    CODE_OF[$pid]=$code
    unset "RUNNING[$pid]"
done

for pid in "${!NAME_OF[@]}"; do
    code=${CODE_OF[$pid]}
    log "${NAME_OF[$pid]}: exit code $code"
    [[ $code == 0 ]] || failed=1
done
if [[ -n $mission && $mission_code != 0 ]]; then
    log 'mission did not succeed'
    failed=1
fi
exit "$failed"
