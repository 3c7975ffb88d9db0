#!/usr/bin/env bash
# Print the Fast DDS layout facts that the guard's build takes from one set of headers: the same
# probe as setup.py's (cft_action/native/_fastdds_layout.cpp, compiled to assembly; nothing is linked or
# run), and the build options of the headers' fastrtps/config.h.
#   compat/probe.sh VENV            the wheels' headers (VENV/include)
#   compat/probe.sh VENV STACK      a stack's installed headers (STACK/install/include/fastrtps),
#                                   the venv's fastcdr and foonathan_memory headers after them
# Fast DDS 3 headers (fastdds/config.hpp: a Kilted venv's VENV/include, a Fast DDS 3 stack's
# STACK/install/include/fastdds) give their build options only: the layout probe is 2.14's.
set -euo pipefail
venv=$(realpath "$1"); stack=${2:+$(realpath "$2")}
root=$(cd "$(dirname "$0")/.." && pwd)
if [ -n "$stack" ]; then three=$stack/install/include/fastdds/fastdds/config.hpp; else three=$venv/include/fastdds/config.hpp; fi
if [ -e "$three" ]; then
  echo "headers: $three"
  grep -E '^#define (HAVE_SECURITY|HAVE_SQLITE3|FASTDDS_VERSION_STR) ' "$three"
  echo "layout probe: Fast DDS 2.14 only (cft_action/native/_fastdds_layout.cpp), not run"
  exit 0
fi
inc=()
if [ -n "$stack" ]; then
  inc+=("-I$stack/install/include/fastrtps")
  [ -e "$stack/install/include/fastrtps/fastrtps/config.h" ] || { echo "probe.sh: no headers in $stack" >&2; exit 2; }
fi
inc+=("-I$venv/include")
config=$(for d in "${inc[@]}"; do f=${d#-I}/fastrtps/config.h; [ -e "$f" ] && { echo "$f"; break; }; done)
echo "headers: $config"
grep -E '^#define (HAVE_SECURITY|HAVE_SQLITE3|FASTRTPS_VERSION_STR) ' "$config"
${CXX:-c++} -std=c++17 -S -o - -fno-access-control -Wno-invalid-offsetof "${inc[@]}" \
  "$root/cft_action/native/_fastdds_layout.cpp" | sed -n 's/^[[:space:]]*->//p'
