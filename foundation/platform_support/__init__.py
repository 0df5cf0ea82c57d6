"""Every operating-system-specific call of the product, and what each does where the OS lacks it.

The product is developed and tested on Linux; a lab may run it on Windows
(where OpenHaptics and the Touch's drivers are most at home) or macOS.  So
nothing outside this module calls what only some systems have -- real-time
scheduling, CPU affinity, ``prctl``, POSIX shared-memory names, signals,
file modes and owners, ``O_NOFOLLOW`` and the other ``open`` flags,
``statvfs``/``sysconf``, ``ctypes`` into the C library
(``tests/pipeline/test_platform_support.py`` scans the source for them).
Each function here makes the Linux call exactly as the product always did,
and elsewhere does the documented fallback below; ``mypy --platform win32``
checks the Windows branches.

=========================== ============================== ===================================================
call                        elsewhere (Windows, macOS)      what the user loses there
=========================== ============================== ===================================================
timer slack (``prctl``)     nothing                        about 50 µs more median wake-up lateness of the loop
``SCHED_FIFO`` (loop and    normal priority; the loop's    the loop can be preempted by any process: a busy
helper threads)             ``scheduling`` says why (GUI)  machine shows in the loop's jitter figures
usable CPUs (affinity)      ``os.cpu_count()``             a CPU mask (``taskset``) is not honoured
the loop's process pinned   nothing                        the scheduler places the loop on any CPU (it may
to one CPU                                                  migrate; the health panel says "any CPU")
a process started with a    Windows: not done (None)       the 1 kHz loop runs in a thread of the study
socket open in it                                           engine's process and shares its interpreter lock
(``pass_fds``)                                              with the engine's other work, as before
worker processes            ``spawn``                      each worker imports the product afresh (slower
(``fork``)                                                  start of a parallel study)
die with the parent         nothing                        a killed command leaves its worker processes to
(``PR_SET_PDEATHSIG``;                                      finish their task (``run``: their participant,
:func:`die_with`)                                           each under its own session's lease)
hard kill (``SIGKILL``)     Windows: ``TerminateProcess``  nothing: both end the process with no clean-up
process exists (kill 0)     Windows: ``OpenProcess``       nothing (Windows' ``kill(pid, 0)`` would send
                                                            Ctrl-C, so it is never used there)
shared memory by name       ``SharedMemory(name)``         Windows: nothing (a segment dies with its last
(``/dev/shm``)                                              handle, so no orphan is left); macOS: the same
                                                            calls through ``shm_open``
owner-only study file       Windows: nothing               the file keeps its folder's access rights (ACL)
(``chmod 0600``)
file modes, umask,          Windows: no ``*at`` calls:     the same policy, but each step is a look then an
``O_NOFOLLOW``, ``dir_fd``  :data:`DIR_FD_CALLS` False:    act: a process that changes the output folder
                            the output policy walks paths, between the two (puts a link or junction where a
                            ``lstat``-checking each part   checked folder was) can win that race; the ``*at``
                            (no link, no junction: see     calls leave no such window.  New files keep the
                            :func:`redirects`) right       folder's access rights (no 0600)
                            before each open, rename and
                            remove (:mod:`foundation.outpath`)
free disk space             ``shutil.disk_usage``          nothing
(``statvfs``)
read-only mount             not detected ahead             the write fails instead, with the OS's error in
(``ST_RDONLY``)                                            one line
free memory (``sysconf``)   Windows: ``GlobalMemory-       nothing (untested on Windows)
                            StatusEx``
load average                None                           benchmarks print no load
jitter tracing (``pread``   nothing (tracer reads zeros)   ``--explain`` names no cause for a late tick
of ``/proc``, GIL kept)
process identity (boot id,  "" (``/proc`` absent)          a reused process id is not told apart from the
start time in ``/proc``)                                   lease's writer: the lease trusts its heartbeat
zombie check (``/proc``)    ``process_exists`` alone       a killed writer not yet reaped counts as alive
free memory (MemAvailable,  free physical memory only      the memory check is stricter (page cache not
cgroup v2 limit)                                           counted) and blind to a container's limit
CPU times (``/proc/stat``)  None                           benchmarks print no hypervisor steal
DLL search path             Linux, macOS: nothing (the     nothing: ``[haptic] dll_dir`` only tells Windows
(``add_dll_directory``)     loader's own path)             where HD.dll is
=========================== ============================== ===================================================

The garbage-collector and switch-interval settings of the loop's process
(:func:`pipeline.core.clock.manual_garbage_collection`, ``sys.setswitchinterval``)
are CPython's, the same on every system, so they are not here.

The calls live in one module per job: :mod:`~foundation.platform_support.threads` (the loop's threads),
:mod:`~foundation.platform_support.processes`, :mod:`~foundation.platform_support.shared_memory`,
:mod:`~foundation.platform_support.files` and :mod:`~foundation.platform_support.machine`; what each asks first
(is this Linux, the C library) is :mod:`~foundation.platform_support.system`.
"""
