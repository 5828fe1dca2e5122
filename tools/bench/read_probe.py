#!/usr/bin/env python3
"""read_probe.py FILE THREADS SIZE COUNT: how a disk serves random reads.

Reads COUNT blocks of SIZE bytes at random page-aligned offsets of FILE
(seed 1) from THREADS threads (os.pread releases the GIL, so THREADS reads
are in flight), with POSIX_FADV_RANDOM (no kernel read-ahead), and prints
the time, reads per second and MB/s. Drop the page cache first for a cold
disk (`sync; echo 3 > /proc/sys/vm/drop_caches`, as root). Used to choose
the brick reader's window sizes (docs/scale.md, "One frame under memory limits"), e.g.

  for cfg in "2 4096 20000" "8 4096 20000" "2 1048576 400" "8 1048576 400"; do
    sync; echo 3 > /proc/sys/vm/drop_caches; tools/bench/read_probe.py STORE/bricks.vxb $cfg
  done
"""
import os
import random
import sys
import threading
import time


def main():
    if len(sys.argv) != 5:
        sys.exit(__doc__)
    path = sys.argv[1]
    nthreads, size, count = (int(a) for a in sys.argv[2:])
    fd = os.open(path, os.O_RDONLY)
    fsz = os.fstat(fd).st_size
    if fsz <= size:
        sys.exit(f"read_probe: {path} is smaller than one read of {size} bytes")
    os.posix_fadvise(fd, 0, 0, os.POSIX_FADV_RANDOM)
    rng = random.Random(1)
    offs = [rng.randrange(0, fsz - size) // 4096 * 4096 for _ in range(count)]

    def work(i):
        for o in offs[i::nthreads]:
            os.pread(fd, size, o)

    t = time.monotonic()
    threads = [threading.Thread(target=work, args=(i,)) for i in range(nthreads)]
    for th in threads:
        th.start()
    for th in threads:
        th.join()
    dt = time.monotonic() - t
    print(f"threads={nthreads} size={size} count={count} {dt:.2f} s {count / dt:.0f} reads/s "
          f"{count * size / dt / 1e6:.0f} MB/s")


if __name__ == "__main__":
    main()
