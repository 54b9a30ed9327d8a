#!/usr/bin/env bash
# Start the uav_tilt node graph in namespace /uav, each node its own process (DESIGN §6).
#
# usage: scripts/launch.sh [--scenario F] [--realtime] [--record DIR] [--foxglove]
#          [--mission inspect | --mission plan --plan FILE] [--no-vision] [--record-images P]
#          [--target-source vision|ground_truth] [--vision-only] [--param NODE.NAME:=VALUE]...
#
# Lockstep unless --realtime. With --mission plan the controller runs the plan FILE, its site
# (the wall, the target ids) taken from the scenario as a survey would give it.
# Ctrl-C or SIGTERM sends SIGINT to every node (as ros2 launch
# does: every node shuts down cleanly on it); nodes still running after UAV_TILT_GRACE_S
# (5, whole) seconds are killed. Should this script be killed outright (SIGKILL), its
# nodes get SIGTERM from the kernel (UAV_TILT_PARENT_PID, uav_tilt_common/parent_watch.py)
# and end themselves after the same grace should their shutdown hang.
# Exit 0 only when every node stopped cleanly and, with --mission, the mission succeeded;
# 2 when an option, the scenario or a node's parameters were refused.
# --vision-only starts vision alone: the companion computer's side of a two-computer run,
# whose other side is --no-vision. --param sets one parameter of one node (plant,
# controller, vision, recorder, foxglove), e.g. --param controller.contact_force:=4.0.
# Discovery is local-only unless ROS_AUTOMATIC_DISCOVERY_RANGE is set; ROS_DOMAIN_ID and
# ROS_STATIC_PEERS pass through. Executables come from .venv/bin, else PATH, else
# `python -m`. At the end it prints the plant's timing (mode, achieved real-time factor,
# late commands, dropped ticks).
set -euo pipefail

usage() { sed -n '4,6p' "${BASH_SOURCE[0]}" | sed 's/^# //'; }
# --help: the usage, then each option on a line of its own (docs/running.md has the rest).
help() {
    usage
    cat <<'EOF'

Starts the uav_tilt node graph in namespace /uav, each node its own process; Ctrl-C stops
every node. Exit 0 when every node stopped cleanly and the mission (if any) succeeded, 2
when an option, the scenario or a node's parameters were refused, else 1.

options:
  --scenario FILE           the world (default: config/scenarios/default.yaml)
  --realtime                pace the plant by the wall clock (default: lockstep)
  --record DIR              record the run to DIR/recording.mcap (uav-tilt report DIR)
  --record-images P         camera images kept: all, thin (6 a second), none (default: all)
  --foxglove                also start the live view (ws://127.0.0.1:8765)
  --mission inspect|plan    fly the mission at once, its log on stdout, and end with it
  --plan FILE               with --mission plan: the inspection plan (YAML)
  --no-vision               start no vision node (it runs elsewhere: --vision-only)
  --target-source SOURCE    vision or ground_truth (default: config/controller.yaml's)
  --vision-only             start vision alone (the companion computer's side)
  --param NODE.NAME:=VALUE  a parameter of plant, controller, vision, recorder or foxglove
  -h, --help                this help
EOF
}
log() { echo "[launch] $*" >&2; }
die() { log "$*"; usage >&2; exit 2; }

if ((BASH_VERSINFO[0] < 5 || (BASH_VERSINFO[0] == 5 && BASH_VERSINFO[1] < 1))); then
    echo "[launch] needs bash >= 5.1 (wait -n -p)" >&2
    exit 2
fi

REPO=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
CONFIG=$REPO/config
GRACE_S=${UAV_TILT_GRACE_S:-5}
# A node whose shutdown hangs after this script was killed ends itself after the same grace.
export UAV_TILT_GRACE_S=$GRACE_S

scenario='' realtime=0 record='' mission='' plan='' foxglove=0 vision=1 target_source=''
vision_only=0 record_images=''
PARAMS=()
# Parameters the script sets from its own options: a --param for one would split what the
# nodes are told (the plant's scenario against the plan's site, say), so it is refused.
declare -A OWNED_BY=(
    [plant.scenario_file]=--scenario [foxglove.scenario_file]=--scenario
    [plant.mode]=--realtime [controller.autostart]=--mission [controller.plan_file]=--plan
    [controller.target_source]=--target-source [recorder.output]=--record
    [recorder.images]=--record-images
    [plant.hold_until_recorded]=--record [controller.hold_until_recorded]=--record
    [plant.summary_file]='the script (its timing line at the end)'
)
while (($#)); do
    case $1 in
        --scenario) scenario=${2:-}; [[ -n $scenario ]] || die '--scenario needs a file'; shift 2 ;;
        --realtime) realtime=1; shift ;;
        --record) record=${2:-}; [[ -n $record ]] || die '--record needs a directory'; shift 2 ;;
        --record-images)
            record_images=${2:-}
            [[ $record_images == all || $record_images == thin || $record_images == none ]] \
                || die '--record-images: all, thin or none'
            shift 2 ;;
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
        --vision-only) vision_only=1; shift ;;
        --param)
            [[ ${2:-} =~ ^(plant|controller|vision|recorder|foxglove)\.[A-Za-z0-9_.]+:=.+ ]] \
                || die "--param: NODE.NAME:=VALUE with NODE one of plant, controller, vision, recorder, foxglove"
            owner=${OWNED_BY[${2%%:=*}]:-}
            [[ -z $owner ]] || die "--param ${2%%:=*}: set by $owner"
            PARAMS+=("$2")
            shift 2 ;;
        -h | --help) help; exit 0 ;;
        *) die "unknown argument: $1" ;;
    esac
done

[[ -z $record_images || -n $record ]] || die '--record-images goes with --record DIR'
if [[ $mission == plan && -z $plan ]] || [[ -n $plan && $mission != plan ]]; then
    die '--mission plan and --plan FILE go together'
fi
[[ -z $plan || -f $plan ]] || die "--plan: no file $plan"
if ((vision_only)) && [[ -n $record$mission$scenario$target_source ]] \
        || ((vision_only && (foxglove || !vision || realtime))); then
    die '--vision-only starts vision alone: it takes no other option but --param'
fi
if ((!vision)) && [[ -n $mission && $target_source != ground_truth ]]; then
    log 'note: with --no-vision the controller gets its target from a vision node elsewhere' \
        '(--vision-only on the companion computer) or none (--target-source ground_truth?)'
fi

export ROS_AUTOMATIC_DISCOVERY_RANGE=${ROS_AUTOMATIC_DISCOVERY_RANGE:-LOCALHOST}
export PYTHONUNBUFFERED=1
# Each node arms a parent-death signal against this pid (uav_tilt_common/parent_watch.py).
export UAV_TILT_PARENT_PID=$$

if [[ -x $REPO/.venv/bin/python ]]; then
    BIN=$REPO/.venv/bin
    PY=$BIN/python
else
    BIN=''
    PY=$(command -v python3) || die 'no .venv and no python3 on PATH'
fi

# The scenario is read here as well as by the plant, so that a missing or bad file (or, for
# --mission inspect, one that designates no target) is one line and exit 2 before anything
# starts; its site (wall, target ids) is what --plan needs.
if ((!vision_only)); then
    site=$("$PY" -m uav_tilt_tools.runner.site_params "$scenario" "$mission") \
        || { usage >&2; exit 2; }
fi
# A folder that holds a bag (ours, or another tool's) is refused: it would be overwritten or
# mixed, and the recorder would refuse it only once the graph is up.
if [[ -n $record ]]; then
    "$PY" -m uav_tilt_tools.bag.folder "$record" || { usage >&2; exit 2; }
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

# CMD += the ROS arguments of node $1: its parameter file (if any) and use_sim_time (not for
# the plant, which owns time, nor for the mission watcher, which only reads status: sim
# time would cost it a /clock message every control tick). `start` adds the --param values
# last, so that they win over these and over what the script sets itself.
ros_args() {
    CMD+=(--ros-args -r __ns:=/uav)
    [[ ! -f $CONFIG/$1.yaml ]] || CMD+=(--params-file "$CONFIG/$1.yaml")
    [[ $1 == plant || $1 == mission_watch ]] || CMD+=(-p use_sim_time:=true)
}

# --realtime: the plant and the controller (the 300 Hz loop) and vision run with real-time
# scheduling (SCHED_FIFO, UAV_TILT_RT_PRIORITY, vision 10 below) where the user may use it,
# so that other work on the machine does not delay a tick; the kernel keeps 5% of each core
# for everything else. UAV_TILT_RT_PRIORITY=0 turns it off.
RT_PRIORITY=${UAV_TILT_RT_PRIORITY:-50}
rt_ok=0
if ((realtime && RT_PRIORITY > 0)); then
    if command -v chrt >/dev/null && chrt -f "$RT_PRIORITY" true 2>/dev/null; then
        rt_ok=1
    else
        log "warning: real-time scheduling not permitted (chrt -f $RT_PRIORITY):" \
            "the 300 Hz loop shares the cores with everything else"
    fi
fi
# CMD := chrt -f PRIORITY CMD, with --realtime where permitted.
realtime_priority() {
    ((!rt_ok)) || CMD=(chrt -f "$1" "${CMD[@]}")
}

declare -A NAME_OF=() RUNNING=()
stop_signal=0
# Before the nodes run, a signal stops the start-up; from then on it starts the shutdown.
trap 'stop_signal=1' INT TERM
# Should this script fail, no node outlives it.
# shellcheck disable=SC2329  # invoked by the EXIT trap
# The plant writes its timing (real-time factor, late commands, ...) here at exit.
PLANT_SUMMARY=$(mktemp "${TMPDIR:-/tmp}/uav_tilt_plant.XXXXXX")
# A node that refuses its parameters or files writes why to $REFUSED.<name> as well as to
# stderr (UAV_TILT_REFUSAL_FILE, uav_tilt_common/ros_params.py): the last lines repeat it.
REFUSED=$PLANT_SUMMARY.refused
kill_all() {
    local p
    for p in "${!RUNNING[@]}"; do kill -s KILL -- "-$p" 2>/dev/null || true; done
    rm -f "$PLANT_SUMMARY" "$REFUSED".*
}
trap kill_all EXIT

start() {
    local name=$1 p
    ((!stop_signal)) || return 0
    for p in ${PARAMS[@]+"${PARAMS[@]}"}; do
        [[ $p != "$name".* ]] || CMD+=(-p "${p#"$name".}")
    done
    # Job control gives each node its own process group, so a terminal's Ctrl-C reaches
    # the nodes once (from here), and their SIGINT is not ignored as in background jobs.
    set -m
    UAV_TILT_REFUSAL_FILE=$REFUSED.$name "${CMD[@]}" </dev/null &
    set +m
    NAME_OF[$!]=$name
    RUNNING[$!]=1
    log "$name (pid $!): ${CMD[*]}"
}

if ((vision_only)); then
    resolve vision_node uav_tilt_vision.vision_node
    ros_args vision
    start vision
fi
if [[ -n $record ]]; then
    resolve recorder_node uav_tilt_tools.bag.recorder_node
    ros_args recorder
    CMD+=(-p "output:=$record")
    [[ -z $record_images ]] || CMD+=(-p "images:=$record_images")
    start recorder
    # It listens once its file exists: wait for that (30 s at most), so that the plant's
    # first tick is recorded.
    recorder_pid=$!
    for ((i = 0; i < 300 && !stop_signal; i++)); do
        [[ ! -e $record/recording.mcap ]] && kill -0 "$recorder_pid" 2>/dev/null || break
        sleep 0.1
    done
fi
if [[ -n $mission ]]; then
    CMD=("$PY" -m uav_tilt_tools.graph.mission_watch)
    ros_args mission_watch
    start mission_watch
fi
if ((foxglove)); then
    resolve foxglove_bridge uav_tilt_tools.graph.foxglove_bridge
    ros_args foxglove
    [[ -z $scenario ]] || CMD+=(-p "scenario_file:=$scenario")
    start foxglove
fi
if ((vision && !vision_only)); then
    resolve vision_node uav_tilt_vision.vision_node
    ros_args vision
    realtime_priority $((RT_PRIORITY > 10 ? RT_PRIORITY - 10 : 1))
    start vision
fi
if ((!vision_only)); then
    resolve controller_node uav_tilt_control.controller_node
    ros_args controller
    [[ -z $target_source ]] || CMD+=(-p "target_source:=$target_source")
    [[ -z $mission ]] || CMD+=(-p "autostart:=$mission")
    if [[ -n $plan ]]; then
        # the site the plan is checked against: the scenario's wall and target ids
        mapfile -t SITE <<<"$site"
        CMD+=(-p "plan_file:=$(realpath "$plan")" "${SITE[@]}")
    fi
    realtime_priority "$RT_PRIORITY"
    [[ -z $record ]] || CMD+=(-p hold_until_recorded:=true)
    start controller
    # The plant owns time: it starts last, so that its first ticks find the others
    # listening.
    resolve plant_node uav_tilt_sim.plant_node
    ros_args plant
    [[ -z $scenario ]] || CMD+=(-p "scenario_file:=$scenario")
    if ((realtime)); then CMD+=(-p mode:=realtime); else CMD+=(-p mode:=lockstep); fi
    # Recorded lockstep runs start once the recorder listens to every plant topic.
    [[ -z $record ]] || CMD+=(-p hold_until_recorded:=true)
    CMD+=(-p "summary_file:=$PLANT_SUMMARY")
    realtime_priority "$RT_PRIORITY"
    start plant
fi
log "ROS_DOMAIN_ID=${ROS_DOMAIN_ID:-0} ROS_AUTOMATIC_DISCOVERY_RANGE=$ROS_AUTOMATIC_DISCOVERY_RANGE"

failed=0
mission_code=''
stopped_by='a stop signal (Ctrl-C)'
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
    stopped_by="$name exiting with code $code"
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

refused=()
for pid in "${!NAME_OF[@]}"; do
    name=${NAME_OF[$pid]}
    code=${CODE_OF[$pid]}
    log "$name: exit code $code"
    [[ $code == 0 ]] || failed=1
    # a node exits 2 when it refuses its parameters or files (DESIGN §6): so does the script
    if [[ $code == 2 && $name != mission_watch ]]; then
        why=''
        [[ ! -s $REFUSED.$name ]] || why=$(head -n 1 "$REFUSED.$name")
        refused+=("$name${why:+: $why}")
    fi
done
if [[ -s $PLANT_SUMMARY ]]; then log "plant timing: $(<"$PLANT_SUMMARY")"; fi
if ((${#refused[@]})); then
    # nothing flew: the refusal is the news, and the last line
    for line in "${refused[@]}"; do log "refused: $line"; done
    exit 2
fi
if [[ -n $mission ]]; then
    if [[ -z $mission_code ]]; then
        log "mission did not finish: stopped by $stopped_by"
        failed=1
    elif [[ $mission_code != 0 ]]; then
        log 'mission did not succeed (its last [mission] lines say how it ended)'
        failed=1
    fi
    if [[ -n $mission_code && -n $record && -s $record/recording.mcap ]]; then
        # the summary's key numbers, by the recorded truth (uav-tilt report draws the plots)
        "$PY" -m uav_tilt_tools.graph.run_summary "$record" || true
    elif [[ -n $mission_code ]]; then
        log 'the POI error against the truth, and the plots, need a recording: --record DIR'
    fi
fi
exit "$failed"
