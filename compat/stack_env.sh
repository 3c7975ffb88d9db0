#!/usr/bin/env bash
# Print the environment (as `export` lines) that runs VENV's python on the Fast DDS + rmw_fastrtps
# of a compatibility stack:   eval "$(compat/stack_env.sh VENV STACK)"
#
# STACK is a directory whose install/lib holds one Fast DDS (libfastrtps.so.2.14 for a Jazzy venv,
# libfastdds.so.3.<minor> for a Kilted one), librmw_fastrtps_shared_cpp.so and librmw_fastrtps_cpp.so
# (see docs/COMPATIBILITY.md). _ROS_WHEELS_BOOTSTRAP_COMPLETE=1 stops
# ros-wheels-bootstrapper from re-executing python with an LD_LIBRARY_PATH of its own (built from a
# set, in no fixed order), so this one, with the stack first, is inherited by every subprocess.
# STACK "wheels" (or empty) prints the same for the wheels' own libraries, in a fixed order.
set -euo pipefail
[ $# -ge 1 ] || { echo "usage: $0 VENV [STACK|wheels]" >&2; exit 2; }
venv=$(realpath "$1"); stack=${2:-wheels}
[ -x "$venv/bin/python" ] || { echo "stack_env.sh: $venv is not a venv" >&2; exit 2; }
first= preload=
if [ "$stack" != wheels ]; then
  stack=$(realpath "$stack")
  # The stack's Fast DDS: 2.14's libfastrtps, or 3.x's libfastdds (the newest 3.<minor> soname there).
  dds=libfastrtps.so.2.14
  if [ ! -e "$stack/install/lib/$dds" ]; then
    dds=$(cd "$stack/install/lib" && ls libfastdds.so.3.* 2>/dev/null | grep -E '^libfastdds\.so\.3\.[0-9]+$' | sort -V | tail -1)
    [ -n "$dds" ] || { echo "stack_env.sh: no libfastrtps.so.2.14 or libfastdds.so.3.* in $stack/install/lib" >&2; exit 2; }
  fi
  for lib in "$dds" librmw_fastrtps_shared_cpp.so librmw_fastrtps_cpp.so; do
    [ -e "$stack/install/lib/$lib" ] || { echo "stack_env.sh: no $lib in $stack/install/lib" >&2; exit 2; }
  done
  first="$stack/install/lib:"
  # The wheels bring their own tinyxml2 (6.0.0, under a hashed soname) and it is mapped before the
  # stack's: unversioned symbols bind to the first definition in scope, so the stack's Fast DDS,
  # compiled against the system's tinyxml2, would run the wheels' (LD_DEBUG=bindings showed
  # XMLDocument's constructor and Parse bound so). Preloading the one it was linked to puts that
  # first; nothing else of the wheels calls tinyxml2 (their Fast DDS and rmw are the ones replaced).
  xml=$(readelf -d "$stack/install/lib/$dds" | sed -n 's/.*NEEDED.*\[\(libtinyxml2[^]]*\)\].*/\1/p')
  if [ -n "$xml" ]; then
    # (awk reads to the end: an early exit would SIGPIPE ldconfig, and pipefail end this script)
    xml=$(ldconfig -p | awk -v n="$xml" '$1 == n && !found { print $NF; found = 1 }')
    [ -n "$xml" ] || { echo "stack_env.sh: the tinyxml2 of $stack is not in ldconfig's cache" >&2; exit 2; }
    preload="$xml${LD_PRELOAD:+:$LD_PRELOAD}"
  fi
fi
libs=$(ls -d "$venv"/lib/python3*/site-packages/ros_*.libs | sort | tr '\n' ':')
echo "export _ROS_WHEELS_BOOTSTRAP_COMPLETE=1"
echo "export LD_LIBRARY_PATH=$first$venv/lib:${libs%:}"
echo "export RMW_IMPLEMENTATION=rmw_fastrtps_cpp"
[ -z "${preload:-}" ] || echo "export LD_PRELOAD=$preload"
