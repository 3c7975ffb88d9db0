# Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
"""Drive a stand-in Fast DDS from two threads; print one JSON line.

    guard_fake_driver.py FAKE_LIBRARY SECONDS [--load-guard-late GUARD_LIBRARY]
    guard_fake_driver.py THROWING_FAKE_LIBRARY --throw

First form (guard_fake_fastdds.c): one thread writes, the other changes and removes filters, on
the same writer, for SECONDS. Second form (guard_fake_throwing.cpp): one thread's write throws
through the guard; then another thread removes a filter of the same writer, which must return.
The fake is loaded with RTLD_LOCAL, as rmw loads Fast DDS. It does not import rclpy or cft_action,
so no real Fast DDS is loaded; the guard's C API is read straight from the global scope.
"""

from __future__ import annotations

import ctypes
import json
import os
import sys
import threading
import time


WRITER = ctypes.c_void_p(0x7f0000001000)  # never dereferenced by the fakes


def throw_then_remove(fake: ctypes.CDLL) -> int:
    fake.fake_write.argtypes = [ctypes.c_void_p, ctypes.c_int]
    fake.fake_remove_filter.argtypes = [ctypes.c_void_p]
    returned: list[int] = []
    writer = threading.Thread(target=lambda: returned.append(fake.fake_write(WRITER, 2)))
    writer.start()
    writer.join(10.0)
    removed = threading.Event()
    remover = threading.Thread(target=lambda: (fake.fake_remove_filter(WRITER), removed.set()),
                               daemon=True)
    remover.start()
    remover.join(5.0)
    print(json.dumps({'write_returned': returned, 'remove_returned': removed.is_set()}),
          flush=True)
    os._exit(0)  # a remover stuck on a lock would keep the process from exiting


def main(argv: list[str]) -> int:
    if argv[1] == '--throw':
        return throw_then_remove(ctypes.CDLL(argv[0]))
    fake_path, seconds = argv[0], float(argv[1])
    fake = ctypes.CDLL(fake_path)  # RTLD_LOCAL
    if len(argv) > 2 and argv[2] == '--load-guard-late':
        ctypes.CDLL(argv[3], mode=ctypes.RTLD_GLOBAL)
    fake.fake_write.argtypes = [ctypes.c_void_p, ctypes.c_int]
    fake.fake_write.restype = ctypes.c_int
    fake.fake_change_filter.argtypes = [ctypes.c_void_p]
    fake.fake_remove_filter.argtypes = [ctypes.c_void_p]
    writer = WRITER
    wrong = []
    end = time.monotonic() + seconds

    def write() -> None:
        while time.monotonic() < end:
            if fake.fake_write(writer, 2) != 42:
                wrong.append(1)

    def change() -> None:
        while time.monotonic() < end:
            fake.fake_change_filter(writer)
            fake.fake_remove_filter(writer)

    threads = [threading.Thread(target=write), threading.Thread(target=change)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(seconds + 10.0)

    result = {'writes': fake.fake_writes(), 'changes': fake.fake_changes(),
              'overlaps': fake.fake_overlaps(), 'wrong_returns': len(wrong)}
    process = ctypes.CDLL(None)
    if hasattr(process, 'cft_guard_state'):
        process.cft_guard_reason.restype = ctypes.c_char_p
        process.cft_guard_call_count.restype = ctypes.c_ulong
        result['state'] = process.cft_guard_state()
        result['active'] = process.cft_guard_is_active()
        result['reason'] = process.cft_guard_reason().decode()
        result['calls'] = [process.cft_guard_call_count(i) for i in range(4)]
    print(json.dumps(result), flush=True)
    return 0


if __name__ == '__main__':
    sys.exit(main(sys.argv[1:]))
