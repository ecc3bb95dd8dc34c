#!/usr/bin/env bash
# deploy/slurm on a real single-node SLURM: installs Debian's slurmctld, slurmd, slurm-client and munge when
# missing, starts munged, slurmctld and slurmd (no systemd) on 127.0.0.1 with a throwaway configuration, and:
#   1. submits correct-array.sbatch over a simulated mission as a 4-task array (sbatch --wait), runs
#      merge-shards.sbatch with --dependency=afterok, and checks every output byte-identical to one plain
#      `abysslight correct` run, and the merged report listing every photo once, as the one run's does;
#   2. the same with task 3 killed in its first attempt (a stale lock, no report): the array fails, the merge
#      refuses naming shard 3/4, task 3 alone is resubmitted, and the merge then gives the same outputs;
#   3. a cruise of two dives (--cruise) through the same script, each dive merged and identical to its own run;
#   4. one bad photo among the mission's, run by a binary whose path holds a space: every task succeeds (exit 1,
#      some photos failed, counts as done), the afterok merge runs and exits 1, its report naming the photo.
# It stops the daemons it started, by pid. It skips (exit 0, with the reason) only where it cannot be root or
# there is no apt-get. ABYSSLIGHT=path uses that binary instead of building one.
set -euo pipefail
cd "$(dirname "$0")/../.."
repo=$PWD
say() { echo "slurm test: $*"; }
fail() { echo "slurm test: FAILED: $*" >&2; exit 1; }

if [[ $(id -u) != 0 ]]; then
    say "skipped: not root (it installs SLURM and munge with apt-get and starts their daemons)"
    exit 0
fi
if ! command -v apt-get >/dev/null; then
    say "skipped: no apt-get (it installs Debian's slurmctld, slurmd, slurm-client and munge)"
    exit 0
fi
started=$SECONDS

# --- SLURM and munge -----------------------------------------------------------------------------------------
if ! command -v slurmctld >/dev/null || ! command -v slurmd >/dev/null || ! command -v sbatch >/dev/null ||
    ! command -v munged >/dev/null; then
    say "installing slurmctld slurmd slurm-client munge"
    own_policy=
    if [[ ! -e /usr/sbin/policy-rc.d ]]; then
        # The packages must not start their daemons (no systemd here; this test starts its own).
        printf '#!/bin/sh\nexit 101\n' >/usr/sbin/policy-rc.d
        chmod +x /usr/sbin/policy-rc.d
        own_policy=1
    fi
    export DEBIAN_FRONTEND=noninteractive
    apt-get update -qq
    apt-get install -y -qq --no-install-recommends slurmctld slurmd slurm-client munge >/dev/null
    [[ -n $own_policy ]] && rm -f /usr/sbin/policy-rc.d
fi

# --- abysslight ----------------------------------------------------------------------------------------------
if [[ -n ${ABYSSLIGHT:-} ]]; then
    bin=$ABYSSLIGHT
else
    cargo build --release --quiet
    bin=${CARGO_TARGET_DIR:-$repo/target}/release/abysslight
fi
bin=$(realpath "$bin")
[[ -x $bin ]] || fail "no abysslight binary at $bin"

# --- daemons -------------------------------------------------------------------------------------------------
tmp=$(mktemp -d /tmp/abysslight-slurm.XXXXXX)
chmod 755 "$tmp"
pids=()
stop() {
    local p
    for p in "${pids[@]}"; do kill "$p" 2>/dev/null || true; done
    for p in "${pids[@]}"; do
        for _ in $(seq 50); do kill -0 "$p" 2>/dev/null || break; sleep 0.1; done
        kill -9 "$p" 2>/dev/null || true
    done
    rm -rf "$tmp"
}
trap stop EXIT
logs() {
    local f
    for f in "$tmp"/*.log "$tmp"/logs/*; do [[ -f $f ]] && { echo "== $f"; tail -n 30 "$f"; }; done >&2
}

mkdir -p "$tmp/munge" "$tmp/state" "$tmp/spool" "$tmp/logs"
chown munge: "$tmp/munge"
chmod 711 "$tmp/munge"
key=/etc/munge/munge.key
if [[ ! -s $key ]]; then
    mungekey --create --keyfile="$key" 2>/dev/null || dd if=/dev/urandom of="$key" bs=1 count=1024 2>/dev/null
    chown munge: "$key"
    chmod 400 "$key"
fi
sock=$tmp/munge/munge.socket
runuser -u munge -- munged --foreground --socket="$sock" --key-file="$key" \
    --pid-file="$tmp/munge/munged.pid" --log-file="$tmp/munge/munged.log" --seed-file="$tmp/munge/seed" \
    >"$tmp/munged.log" 2>&1 &
pids+=($!)
for _ in $(seq 100); do [[ -S $sock ]] && break; sleep 0.1; done
[[ -S $sock ]] || { logs; cat "$tmp/munge/munged.log" >&2 || true; fail "munged did not start"; }

# The node as slurmd sees it (CPUs, sockets, memory), named localhost on 127.0.0.1.
node=$(slurmd -C | head -1 | sed -e 's/^NodeName=[^ ]*/NodeName=localhost NodeAddr=127.0.0.1/')
port=$((20000 + RANDOM % 20000))
export SLURM_CONF=$tmp/slurm.conf
cat >"$SLURM_CONF" <<EOF
ClusterName=abysslight-test
SlurmctldHost=localhost(127.0.0.1)
SlurmctldPort=$port
SlurmdPort=$((port + 1))
AuthType=auth/munge
AuthInfo=socket=$sock
CredType=cred/munge
SlurmUser=root
SlurmdUser=root
StateSaveLocation=$tmp/state
SlurmdSpoolDir=$tmp/spool
SlurmctldPidFile=$tmp/slurmctld.pid
SlurmdPidFile=$tmp/slurmd.pid
SlurmctldLogFile=$tmp/slurmctld.log
SlurmdLogFile=$tmp/slurmd.log
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
JobCompType=jobcomp/none
SelectType=select/cons_tres
SelectTypeParameters=CR_Core
SchedulerType=sched/builtin
MpiDefault=none
ReturnToService=2
SlurmctldTimeout=30
SlurmdTimeout=30
InactiveLimit=0
KillWait=5
MinJobAge=600
$node State=UNKNOWN
PartitionName=test Nodes=localhost Default=YES MaxTime=INFINITE State=UP
EOF
slurmctld -D -i -f "$SLURM_CONF" >"$tmp/slurmctld.out.log" 2>&1 &
pids+=($!)
slurmd -D -N localhost -f "$SLURM_CONF" >"$tmp/slurmd.out.log" 2>&1 &
pids+=($!)
for _ in $(seq 300); do
    state=$(sinfo -h -N -o %t 2>/dev/null | head -1 || true)
    [[ $state == idle* ]] && break
    sleep 0.2
done
[[ ${state:-} == idle* ]] || { logs; fail "the node did not come up (state '${state:-none}')"; }
say "SLURM $(sinfo -V | awk '{print $2}') up in $((SECONDS - started)) s (node: $node)"

# --- a simulated mission and one plain run of it ------------------------------------------------------------
"$bin" simulate --out "$tmp/sim" --frames 40 --water-column 12 --size 480x360 --seed 7 2>/dev/null
"$bin" correct --water-column "$tmp/sim/water" --survey "$tmp/sim/survey" --out "$tmp/one" --quiet ||
    fail "the plain run failed"
[[ -f $tmp/one/_abysslight/report.json ]] || fail "the plain run wrote no report"

# Every output of the one run byte-identical in OUT, the merged report counting every photo once.
same_as_one() { # OUT ONE PHOTOS
    local out=$1 one=$2 photos=$3 f n
    n=0
    while IFS= read -r -d '' f; do
        cmp -s "$one/$f" "$out/$f" || fail "$out/$f differs from the one run's"
        n=$((n + 1))
    done < <(cd "$one" && find . -path ./_abysslight -prune -o -type f -print0)
    ((n == photos)) || fail "$n outputs in the one run, $photos expected"
    [[ $(cd "$out" && find . -path ./_abysslight -prune -o -type f -print | wc -l) == "$n" ]] ||
        fail "$out holds other outputs than the one run"
    local r=$out/_abysslight/report.json
    [[ -f $r ]] || fail "no merged report in $out"
    grep -q "\"survey_photos\": $photos," "$r" || fail "$r: survey_photos is not $photos"
    grep -q "\"failed\": 0," "$r" || fail "$r: failed photos"
    [[ $(grep -c '^      "input": ' "$r") == "$photos" ]] || fail "$r does not list each of the $photos photos once"
    [[ $(grep '^      "input": ' "$r" | sort -u | wc -l) == "$photos" ]] || fail "$r lists a photo twice"
    grep -q '"shard": null' "$r" || fail "$r keeps a shard's options"
    # The same photos, in the same order, with the same positions in the mission.
    local pat='^      "(input|index)": '
    cmp -s <(grep -E "$pat" "$one/_abysslight/report.json") <(grep -E "$pat" "$r") ||
        fail "$r does not list the photos as the one run's report does"
    [[ -s $out/_abysslight/overview.png ]] || fail "no merged overview.png in $out"
}

submit_array() { # ARRAY-ARGS... -- CORRECT-ARGS...: prints the job id; waits; returns sbatch's status
    local opts=()
    while [[ $1 != -- ]]; do opts+=("$1"); shift; done
    shift
    sbatch --parsable --wait --mem=300M --cpus-per-task=1 --output="$tmp/logs/%A_%a.out" "${opts[@]}" \
        "$repo/deploy/slurm/correct-array.sbatch" "$@"
}

# --- 1. the array and the merge -----------------------------------------------------------------------------
t=$SECONDS
args=(--water-column "$tmp/sim/water" --survey "$tmp/sim/survey" --out "$tmp/arr")
job=$(ABYSSLIGHT=$bin submit_array --array=1-4 -- "${args[@]}") || { logs; fail "the array failed"; }
merge=$(ABYSSLIGHT=$bin sbatch --parsable --wait --dependency="afterok:$job" --output="$tmp/logs/merge-%j.out" \
    "$repo/deploy/slurm/merge-shards.sbatch" "${args[@]}") || { logs; fail "the merge job failed"; }
same_as_one "$tmp/arr" "$tmp/one" 40
say "1. array of 4 + merge (jobs $job, $merge): 40 outputs identical to one run, one report ($((SECONDS - t)) s)"

# --- 2. a task killed, resubmitted alone --------------------------------------------------------------------
t=$SECONDS
cat >"$tmp/kill-task-3.sh" <<EOF
#!/bin/bash
# Task 3's first attempt is killed (SIGKILL, as at a time or memory limit) once it holds its lock.
if [[ \$SLURM_ARRAY_TASK_ID == 3 && ! -e $tmp/killed-once ]]; then
    touch $tmp/killed-once
    "$bin" "\$@" & pid=\$!
    lock=$tmp/res/_abysslight/lock-shard-3-of-4
    while [[ ! -e \$lock ]] && kill -0 \$pid 2>/dev/null; do :; done
    kill -9 \$pid
    wait \$pid
    exit # with the status of the killed run
fi
exec "$bin" "\$@"
EOF
chmod +x "$tmp/kill-task-3.sh"
args=(--water-column "$tmp/sim/water" --survey "$tmp/sim/survey" --out "$tmp/res")
if ABYSSLIGHT=$tmp/kill-task-3.sh submit_array --array=1-4 -- "${args[@]}" >/dev/null; then
    fail "the array with a killed task succeeded"
fi
[[ -e $tmp/res/_abysslight/lock-shard-3-of-4 ]] || fail "the killed task left no lock"
[[ ! -e $tmp/res/_abysslight/report-shard-3-of-4.json ]] || fail "the killed task wrote its report"
if msg=$("$bin" merge-shards "$tmp/res" 2>&1); then fail "merge-shards merged without shard 3"; fi
grep -q "shard 3/4 has not finished" <<<"$msg" || fail "merge-shards did not name shard 3/4: $msg"
ABYSSLIGHT=$bin ABYSSLIGHT_SHARDS=4 submit_array --array=3 -- "${args[@]}" >/dev/null ||
    { logs; fail "the resubmitted task failed"; }
"$bin" merge-shards --quiet "$tmp/res" || fail "merge-shards after the resubmission failed"
same_as_one "$tmp/res" "$tmp/one" 40
say "2. task 3 killed: the merge named it; resubmitted alone (--array=3, ABYSSLIGHT_SHARDS=4): identical ($((SECONDS - t)) s)"

# --- 3. a cruise of two dives -------------------------------------------------------------------------------
t=$SECONDS
for d in 1 2; do
    dive=$tmp/cruise/dive$d
    "$bin" simulate --out "$dive" --frames 16 --water-column 8 --size 320x240 --seed $((10 + d)) 2>/dev/null
    mv "$dive/water" "$dive/water-column"
    "$bin" correct --water-column "$dive/water-column" --survey "$dive/survey" --out "$tmp/one$d" --quiet
done
mkdir "$tmp/cruise/notes" # not a dive: no survey/
job=$(ABYSSLIGHT=$bin submit_array --array=1-3 -- --cruise "$tmp/cruise" --out "$tmp/cr") ||
    { logs; fail "the cruise array failed"; }
ABYSSLIGHT=$bin sbatch --parsable --wait --dependency="afterok:$job" --output="$tmp/logs/merge-%j.out" \
    "$repo/deploy/slurm/merge-shards.sbatch" "$tmp/cr" >/dev/null || { logs; fail "the cruise merge failed"; }
same_as_one "$tmp/cr/dive1" "$tmp/one1" 16
same_as_one "$tmp/cr/dive2" "$tmp/one2" 16
say "3. cruise of 2 dives as an array of 3: each dive identical to its own run ($((SECONDS - t)) s)"

# --- 4. one bad photo among many; a binary whose path holds a space -----------------------------------------
t=$SECONDS
mkdir -p "$tmp/bad" "$tmp/with space"
cp -r "$tmp/sim/survey" "$tmp/bad/survey"
bad=$(cd "$tmp/bad/survey" && find . -type f -printf '%P\n' | sort | sed -n 5p)
printf 'not a photo' >"$tmp/bad/survey/$bad"
spaced="$tmp/with space/abysslight"
cp "$bin" "$spaced"
args=(--water-column "$tmp/sim/water" --survey "$tmp/bad/survey" --out "$tmp/badout")
job=$(ABYSSLIGHT=$spaced submit_array --array=1-4 -- "${args[@]}") ||
    { logs; fail "one bad photo (or the space in ABYSSLIGHT) failed the array: exit 1 must count as done"; }
rc=0
ABYSSLIGHT=$spaced sbatch --parsable --wait --dependency="afterok:$job" --output="$tmp/logs/merge-%j.out" \
    "$repo/deploy/slurm/merge-shards.sbatch" "$tmp/badout" >/dev/null || rc=$?
((rc == 1)) || { logs; fail "the merge of a mission with one bad photo exited $rc, 1 expected"; }
r=$tmp/badout/_abysslight/report.json
grep -q '"failed": 1,' "$r" || fail "$r does not count the bad photo"
grep -q "$bad" "$r" || fail "$r does not name $bad"
say "4. one bad photo, ABYSSLIGHT with a space: array succeeded, merge ran and exited 1 naming it ($((SECONDS - t)) s)"

say "all done in $((SECONDS - started)) s"
echo "slurm: 4 passed, 0 failed"
