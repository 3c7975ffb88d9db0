#!/usr/bin/env bash
# Print the guard's Fast DDS layout facts (compat/layout_probe.cpp) for one set of headers.
#   compat/probe.sh VENV            the wheels' headers (VENV/include)
#   compat/probe.sh VENV STACK      a stack's installed headers (STACK/install/include/fastrtps),
#                                   the venv's fastcdr and foonathan_memory headers after them
# Linked to that Fast DDS (rpath) for its static constants; no Fast DDS object is constructed.
set -euo pipefail
venv=$(realpath "$1"); stack=${2:+$(realpath "$2")}
here=$(cd "$(dirname "$0")" && pwd)
inc=() lib=()
if [ -n "$stack" ]; then
  inc+=("-I$stack/install/include/fastrtps") lib+=("$stack/install/lib")
  [ -e "$stack/install/include/fastrtps/fastrtps/config.h" ] || { echo "probe.sh: no headers in $stack" >&2; exit 2; }
fi
inc+=("-I$venv/include") lib+=("$venv/lib")
links=(); for d in "${lib[@]}"; do links+=("-L$d" "-Wl,-rpath,$d"); done
out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT
${CXX:-c++} -std=c++17 -Wno-invalid-offsetof "${inc[@]}" "$here/layout_probe.cpp" -o "$out/probe" \
  "${links[@]}" -lfastrtps -lfastcdr -Wl,--unresolved-symbols=ignore-in-shared-libs
# The wheels' libraries find their vendored ones (ros_*.libs) only through LD_LIBRARY_PATH.
libs=$(ls -d "$venv"/lib/python3*/site-packages/ros_*.libs | sort | tr '\n' ':')
LD_LIBRARY_PATH="$(IFS=:; echo "${lib[*]}"):${libs%:}" "$out/probe"
