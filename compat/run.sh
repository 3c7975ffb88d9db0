#!/usr/bin/env bash
# Run test files of this repository on compatibility stacks (see docs/COMPATIBILITY.md).
#
#   compat/run.sh VENV CACHE "STACK..." TEST_FILE...
#
# VENV   the venv whose python runs the tests (make's .venv: cft_action installed, guard built).
# CACHE  the directory that holds the stacks, CACHE/<stack>/install/lib/...
# STACK  a stack name under CACHE, or `wheels` for the venv's own libraries (the baseline).
#
# A stack is prebuilt (docs/COMPATIBILITY.md, "The stacks"); a missing one fails and says so.
# For each stack: its environment (compat/stack_env.sh) is exported, so pytest and every process
# the tests start load that stack's Fast DDS and rmw_fastrtps; compat/verify_stack.py checks it
# is really mapped and that plain ROS works on it; then pytest runs the files. Output goes to
# CACHE/results/<stack>-<UTC time>/ (probe.txt: compat/probe.sh's layout facts of the stack's
# headers; verify.txt, pytest.txt, junit.xml, summary.txt).
# Exit status: 1 if any stack failed verification or any test failed.
set -uo pipefail
[ $# -ge 4 ] || { echo "usage: $0 VENV CACHE \"STACK...\" TEST_FILE..." >&2; exit 2; }
venv=$(realpath "$1"); cache=$(realpath -m "$2"); stacks=$3; shift 3
here=$(cd "$(dirname "$0")" && pwd); root=$(dirname "$here")
cd "$root"
status=0
wheels() {  # the ROS wheel versions a venv has (Jazzy's Fast DDS is ros-fastrtps, Kilted's ros-fastdds)
  "$1/bin/python" -c 'import importlib.metadata as m
def v(p):
    try:
        return [p + "==" + m.version(p)]
    except m.PackageNotFoundError:
        return []
print(" ".join(sum((v(p) for p in ("ros-fastrtps", "ros-fastdds", "ros-rmw-fastrtps-shared-cpp",
      "ros-rmw-fastrtps-cpp", "ros-rcl", "ros-rclpy")), [])))'
}
have=$(_ROS_WHEELS_BOOTSTRAP_COMPLETE=0 wheels "$venv")
for stack in $stacks; do
  dir=$cache/$stack
  if [ "$stack" != wheels ] && [ ! -e "$dir/install/lib/librmw_fastrtps_cpp.so" ]; then
    echo "== $stack: no stack in $dir (install/lib/librmw_fastrtps_cpp.so; docs/COMPATIBILITY.md)"
    status=1; continue
  fi
  if [ "$stack" != wheels ]; then
    built=$(sed -n 's/^venv_wheels=//p' "$dir/STACK_INFO" | tail -1)
    if [ "$built" != "$have" ]; then
      echo "== $stack: built against wheels [$built], but $venv has [$have]: not this venv's stack"
      status=1; continue
    fi
  fi
  out=$cache/results/$stack-$(date -u +%Y%m%dT%H%M%SZ); mkdir -p "$out"
  (
    target=$dir; [ "$stack" = wheels ] && target=wheels
    exports=$("$here/stack_env.sh" "$venv" "$target") || { echo "== $stack: no environment"; exit 1; }
    eval "$exports"
    {
      echo "stack=$stack"; echo "dir=$dir"; echo "when=$(date -u +%FT%TZ)"
      echo "cft_action=$(git -C "$root" rev-parse HEAD)$(git -C "$root" diff --quiet HEAD -- cft_action tests || echo ' (dirty)')"
      [ "$stack" != wheels ] && cat "$dir/STACK_INFO"
      echo "LD_LIBRARY_PATH=$LD_LIBRARY_PATH"; echo "LD_PRELOAD=${LD_PRELOAD:-}"
    } > "$out/summary.txt"
    if [ "$stack" = wheels ]; then "$here/probe.sh" "$venv"; else "$here/probe.sh" "$venv" "$dir"; fi \
      > "$out/probe.txt" 2>&1 || echo "== $stack: the layout probe failed ($out/probe.txt)"
    echo "== $stack: verify ($out/verify.txt)"
    timeout 180 nice -n 19 "$venv/bin/python" -m compat.verify_stack "$target" \
      > "$out/verify.txt" 2>&1
    v=$?; tail -1 "$out/verify.txt"; echo "verify_exit=$v" >> "$out/summary.txt"
    echo "== $stack: pytest $* ($out/pytest.txt)"
    nice -n 19 "$venv/bin/python" -m pytest -p no:cacheprovider -rA --junitxml="$out/junit.xml" "$@" \
      > "$out/pytest.txt" 2>&1
    p=$?; tail -1 "$out/pytest.txt"; echo "pytest_exit=$p" >> "$out/summary.txt"
    grep -h 'filter verdicts off[^"]*' -o "$out/pytest.txt" | sort | uniq -c | head -5 \
      | sed 's/^/guard said: /' | tee -a "$out/summary.txt"
    [ $v -eq 0 ] && [ $p -eq 0 ]
  ) || status=1
done
exit $status
