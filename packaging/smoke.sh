#!/usr/bin/env bash
# The wheel as a user gets it (CI runs this after `make test`): built from this checkout's HEAD,
# installed with every bus extra into an empty virtual environment, then, from outside the
# checkout: --version, `orccadctl check` on every shipped mission (its tasks built on the shipped robot whose resources it names),
# the service files, completion, the module catalogue, orccadd on the shipped
# sim-ur5e config for two seconds, status, and a SIGTERM that must end it cleanly (exit 0).
set -euo pipefail
here="$(cd "$(dirname "$0")/.." && pwd)"
work="$(mktemp -d)"
pid=""
cleanup() { [ -n "$pid" ] && kill "$pid" 2>/dev/null || true; rm -rf "$work"; }
trap cleanup EXIT

python3 -m venv "$work/venv"
bin="$work/venv/bin"
"$bin/python" -m pip install --quiet --upgrade pip
wheel="$("$here/packaging/build-wheel.sh" "$work/dist")"  # what the repository holds, nothing untracked
"$bin/python" -m pip install --quiet "${wheel}[all]"

cd "$work"  # nothing of the checkout from here on
"$bin/orccadd" --version
"$bin/orccadctl" --version
"$bin/orccadd-vcan" --help >/dev/null  # the CANopen tour's virtual bus, from the wheel
"$bin/orccadd" --list-configs
share="$work/venv/share/orccadd/configs"
for mission in "$share"/missions/*.mission; do
    if grep -q '^task .* from "' "$mission"; then
        # the shipped robot whose resources the mission names (`resource ...`)
        case "$(grep -m1 '^resource ' "$mission")" in
            "resource arm") robot=sim-ur5e ;;  # a UR's digital I/O: below
            "resource gripper") robot=gripper-sim ;;
            "resource arm, gripper") robot=ur5e-gripper-sim ;;
            "resource left, right") robot=dual-arm-sim ;;
            "resource left, right, left_hand, right_hand") robot=dual-arm-grippers-sim ;;
            *) echo "smoke: no shipped robot for $(basename "$mission")" >&2; exit 1 ;;
        esac
        # a mission using the arm's named digital I/O (`input arm.X`) needs the UR that names them
        if grep -q '^input .*arm\.' "$mission"; then robot=ur5e-rtde-sim; fi
        # and one whose tasks need the UR controller (force mode, freedrive, its sensor, its slider)
        if grep -Eq 'from "\.\./tasks/(ur_|approach_until_contact)' "$mission"; then robot=ur5e-rtde-sim; fi
        # a camera's features (visual servoing) are the work cell's simulated arm's
        if grep -Eq 'from "\.\./tasks/(keepstable_cam|servo_visual)' "$mission"; then robot=sim-ur5e-workcell; fi
        "$bin/orccadctl" check "$mission" --config "$robot" >/dev/null  # every task built on it
        echo "checked $(basename "$mission") (and its tasks on $robot)"
    else  # the seed's KEEPSTABLE (an underwater vehicle): no task files for an arm
        "$bin/orccadctl" check --language-only "$mission" >/dev/null
        echo "checked $(basename "$mission") (language and automaton: it has no task files)"
    fi
done

for f in systemd/orccadd.service systemd/orccadd-can@.service udev/60-orccadd-cpu-dma-latency.rules \
         udev/60-orccadd-dynamixel.rules; do  # what docs/install.md installs from the wheel
    [ -f "$work/venv/share/orccadd/$f" ] || { echo "smoke: the wheel lacks share/orccadd/$f" >&2; exit 1; }
done
[ -f "$work/venv/share/doc/orccadd/install.md" ] || { echo "smoke: the wheel lacks install.md" >&2; exit 1; }
# the cell of PCs (the [cell] extra): its shipped configs, test certificates, a console's refusal
[ -f "$share/cell/arm-a.toml" ] || { echo "smoke: the wheel lacks configs/cell/arm-a.toml" >&2; exit 1; }
"$bin/python" -m orccadd.cellnet.certs "$work/certs" console >/dev/null
if "$bin/orccadctl" --cell "$share/cell/console.toml" cell status 2>"$work/cell.err"; then
    echo "smoke: a console without its certificates must be refused" >&2; exit 1
fi
grep -q "cell.ca .*no such file" "$work/cell.err"
"$bin/orccadctl" completion bash | bash -n
"$bin/orccadctl" modules --config sim-ur5e | grep -q "target_rad .*default required"

sock="$work/run/orccadd.sock"
"$bin/orccadd" --config sim-ur5e --socket "$sock" > "$work/orccadd.log" 2>&1 &
pid=$!
up=""
for _ in $(seq 100); do
    if ORCCADD_SOCKET="$sock" "$bin/orccadctl" status >/dev/null 2>&1; then up=1; break; fi
    sleep 0.2
done
[ -n "$up" ] || { cat "$work/orccadd.log"; echo "smoke: orccadd did not come up" >&2; exit 1; }
sleep 2
ORCCADD_SOCKET="$sock" "$bin/orccadctl" status
kill -TERM "$pid"
code=0
wait "$pid" || code=$?
pid=""
[ "$code" = 0 ] || { cat "$work/orccadd.log"; echo "smoke: orccadd exited $code on SIGTERM" >&2; exit 1; }
echo "smoke: the wheel installs, checks the shipped missions, runs sim-ur5e and stops cleanly"
