"""``hybmss run``: the publication's studies (:mod:`studies.paper.reproduce`) computed into a
results folder, resumable, on this machine's cores or a Dask cluster; the sweep's size and time
are estimated (:func:`sweep_estimate`) and guarded before any work."""

from __future__ import annotations

import os
import signal
import threading

from studies.sweep import sizing
from studies.sweep.executors import EXECUTORS
from studies.sweep.runner import Runner, exit_now
from studies.sweep.store import Store
from studies.paper.reproduce import EXTRA_STUDIES, ON_REQUEST_STUDIES, STUDIES
from studies.cli.common import InputError, guard, working
from studies.cli.options import Options, add_no_guard, integer

HELP = "run the publication's studies and store their results"


def study_names() -> tuple[str, ...]:
    return tuple(STUDIES) + tuple(EXTRA_STUDIES) + tuple(ON_REQUEST_STUDIES)


def add_options(parser, opts: Options) -> None:
    """The options of ``hybmss run``."""
    opts.add(parser, "--study", action="append", default=None, choices=study_names(),
             help="study name (repeatable; default: every study)")
    opts.add(parser, "--all", action="store_true", help="every study of make reproduce-paper")
    opts.add(parser, "--out", default="artifacts/results", help="results folder (default artifacts/results)")
    opts.add(parser, "--quick", action="store_true", help="coarse meshes (the tests' mode)")
    opts.add(parser, "--jobs", type=integer, default=None,
             help="parallel runs, >= 1 (default: all cores, or the Dask cluster's threads)")
    opts.add(parser, "--executor", choices=EXECUTORS, default="local",
             help="local: a process pool on this machine (default); dask: a dask.distributed "
                  "cluster (--scheduler, or a local cluster of --jobs workers)")
    opts.add(parser, "--scheduler", default=None, metavar="ADDRESS",
             help="address of a running dask scheduler, e.g. tcp://host:8786 (--executor dask)")
    opts.add(parser, "--no-progress", action="store_true", help="no progress bar")
    add_no_guard(parser, opts)


def _terminate(signum, frame):
    raise KeyboardInterrupt("SIGTERM")


def sweep_estimate(names, quick: bool, store: Store, workers: int) -> sizing.Estimate:
    """:func:`studies.sweep.sizing.sweep` of the pooled runs of the studies ``names`` (None: all) that
    ``store`` does not hold yet, on ``workers`` workers (the extra studies' own computations, a
    few minutes, are not counted)."""
    import importlib

    from studies.paper.reproduce import tasks_for

    listed = [n for n in (names or study_names()) if n in STUDIES]
    tasks = tasks_for(listed, quick) if listed else []
    for n in (names or study_names()):
        if n in EXTRA_STUDIES:
            module = importlib.import_module(EXTRA_STUDIES[n].split(":")[0])
            tasks += module.tasks(quick) if hasattr(module, "tasks") else []
    stored = set(store.keys())
    pending = {t.key(): t for t in tasks}
    todo = [sizing.task(t.scene, t.solver) for k, t in pending.items() if k not in stored]
    return sizing.sweep(f"sweep of {len(todo)} runs not yet stored", todo, workers)


def run(args):
    """The studies into ``--out``: 0 when the sweep finishes (failed runs are stored rows), 2 for
    options not allowed (checked before any work: the folder, the executor and its scheduler),
    3 when the sweep cannot go on (:class:`studies.sweep.executors.SweepError`), 130 on SIGINT or SIGTERM
    (finished runs are kept, running ones abandoned and their workers stopped; a second Ctrl-C
    exits at once)."""
    from studies.paper.reproduce import check_study_files, run_studies

    if args.all and args.study:
        raise InputError(f"--all and --study {','.join(args.study)} together are not allowed: "
                         "--all runs every study; give one or the other")
    if not str(args.out).strip():
        raise InputError("--out '' is not allowed: a results folder path is required")
    if args.jobs is not None and args.jobs < 1:
        raise InputError(f"--jobs {args.jobs} is not allowed: an integer >= 1 (parallel runs), or none for all cores")
    if args.scheduler is not None and args.executor != "dask":
        raise InputError(f"--scheduler {args.scheduler!r} is given with --executor {args.executor}; a scheduler "
                         "address needs executor dask")
    names = None if args.all else args.study
    check_study_files(names)  # the study files' keys (StudyError: exit 2)
    if args.executor == "local" or args.scheduler is None:  # this machine's workers (a scheduler's are not known)
        workers = args.jobs or os.cpu_count() or 1
        guard(sweep_estimate(names, args.quick, Store(args.out), workers),
              f"run {'--all' if args.all or not args.study else ' '.join('--study ' + n for n in args.study)}"
              + (" --quick" if args.quick else "") + f" on {workers} worker(s)", args=args)
    runner = Runner(args.executor, jobs=args.jobs, scheduler=args.scheduler, progress=not args.no_progress)
    Store(args.out).check_writable()
    main = threading.current_thread() is threading.main_thread()
    # SIGTERM (a job scheduler, `timeout`, `kill`) stops the sweep as Ctrl-C does: no worker is
    # left computing for a process that is gone
    previous = signal.signal(signal.SIGTERM, _terminate) if main else None
    try:
        with runner, working():
            run_studies(args.out, names=names, quick=args.quick, jobs=args.jobs,
                        progress=not args.no_progress, runner=runner)
    except KeyboardInterrupt:
        signal.signal(signal.SIGINT, exit_now)  # exiting; a second Ctrl-C exits at once
        raise KeyboardInterrupt(f"{runner.summary.computed} runs computed and stored in {args.out}, running "
                                "ones abandoned; rerun the same command to resume") from None
    finally:
        if main:
            signal.signal(signal.SIGTERM, previous)
    s = runner.summary
    names = list(STUDIES) + list(EXTRA_STUDIES) if args.all or not args.study else list(args.study)
    return {"out": str(args.out), "studies": names, **s.as_dict()}, f"{args.out}: {s.line()}"
