"""``particles wedge``: check every variant, queue them on the farm, record each result as it
arrives, then draw the contact sheet.

Exit codes: 0 when every variant is ok; 2 for bad input (checked before anything renders);
otherwise the exit code of the first failed variant (3 diverged, 4 output failure, 137 its worker
kept dying); 130 / 143 when stopped by SIGINT / SIGTERM (finish with ``--resume``).
"""
from __future__ import annotations

import os
import statistics
import time
from collections import defaultdict

from ..errors import OutputFailure, Stopped, UserError
from . import record, spec
from .farm import Farm, failure_of
from .progress import WedgeProgress
from .sheet import build_sheet

#: thumbnails (and so contact-sheet cells) are at most this wide
THUMB_WIDTH = 320
_POLL = 0.05  # seconds between looks at finished variants, stop requests and the progress bar
#: local worker processes allowed per core (each holds a Taichi program: 0.2 GB and up)
MAX_WORKERS_PER_CORE = 4


def _check_flags(args, wedge):
    cores = os.cpu_count() or 1
    if args.workers is not None and not 1 <= args.workers <= MAX_WORKERS_PER_CORE * cores:
        raise UserError(f"--workers: {args.workers} is not allowed: must be 1 to "
                        f"{MAX_WORKERS_PER_CORE * cores} ({MAX_WORKERS_PER_CORE} per core here); "
                        f"for more, start a Dask cluster and pass --scheduler")
    if args.workers is not None and args.scheduler:
        raise UserError("--workers and --scheduler: choose one (the cluster at --scheduler has "
                        "its own workers)")
    if args.threads is not None and args.threads < 1:
        raise UserError(f"--threads: {args.threads} is not allowed: must be >= 1")
    if args.scheduler and "://" not in args.scheduler:
        raise UserError(f"--scheduler: {args.scheduler!r} is not an address like tcp://host:8786")
    k = args.sheet_frame
    if k is not None:
        short = min(wedge.variants, key=lambda v: v.frames)
        if k < 0 or k >= short.frames:
            raise UserError(f"--sheet-frame: {k} is not a frame of variant {short.id} "
                            f"(frames 0..{short.frames - 1})")


def _task(args, variant, out, threads) -> dict:
    """What a worker needs for one variant: plain data (its config travels as TOML text, so a
    worker needs no access to the submitter's files, only to ``out``)."""
    return {"id": variant.id, "config_text": variant.config_text,
            "out": record.variant_dir(out, variant.id), "arch": args.arch, "threads": threads,
            "sheet_frame": args.sheet_frame, "thumb_width": THUMB_WIDTH}


def cmd_wedge(args) -> int:
    from ..signals import StopRequest

    t_begin = time.perf_counter()
    wedge = spec.build(args.config, args.set, args.seeds, args.frames, args.size)
    _check_flags(args, wedge)
    out = args.out or os.path.join("renders", f"{wedge.name}_wedge")
    finished = record.check_folder(out, wedge, args.resume)
    todo = [v for v in wedge.variants if v.id not in finished]
    # no more local workers than variants to render: an idle worker costs a start and memory
    workers = None if args.scheduler else max(1, min(args.workers or os.cpu_count() or 1, len(todo)))
    threads = args.threads or (max(1, (os.cpu_count() or 1) // workers) if workers else None)
    progress = WedgeProgress(len(wedge.variants), {v.id: v.frames for v in wedge.variants},
                             args.quiet)
    for vid in finished:
        progress.skipped(vid)
    timing = {"variants_run": len(todo), "skipped": len(finished)}
    results = []
    with StopRequest() as stop:
        t0 = time.perf_counter()
        farm = Farm(workers=workers, scheduler=args.scheduler) if todo else None  # may refuse
        try:
            if farm is not None:
                timing.update(start_s=time.perf_counter() - t0, workers=farm.worker_count,
                              threads_per_worker=threads)
            _create_folder(out, wedge)
            rows = {v.id: record.index_row(wedge, v, finished.get(v.id)) for v in wedge.variants}
            _write_index(out, wedge, rows)
            if farm is not None:
                tasks = [_task(args, v, out, threads) for v in todo]
                _render_all(farm, tasks, wedge, out, rows, progress, results, timing, stop)
        finally:
            if farm is not None:
                farm.close()
        stopped = stop if stop.requested else None
    progress.close()
    t_sheet = time.perf_counter()
    sheet = _sheet(out, wedge, rows)
    timing["sheet_s"] = time.perf_counter() - t_sheet
    timing["wall_s"] = time.perf_counter() - t_begin
    timing.update(_overhead(results, timing))
    _save_record(out, wedge, timing)
    return _summary(wedge, out, rows, sheet, timing, stopped)


def _render_all(farm, tasks, wedge, out, rows, progress, results, timing, stop):
    """Queue the variants on the farm and record each result as it arrives; on SIGINT/SIGTERM
    (``stop``) cancel what is left."""
    by_id = {v.id: v for v in wedge.variants}
    farm.on_frame = progress.frame
    futures = {farm.submit(task): by_id[task["id"]] for task in tasks}
    pending = farm.as_completed(list(futures))
    write_s = []
    while not pending.is_empty():
        for fut in pending.next_batch(block=False):
            res = fut.result() if fut.status == "finished" else failure_of(fut)
            t = time.perf_counter()
            _record(out, wedge, futures[fut], res, rows, progress)
            write_s.append(time.perf_counter() - t)
            results.append(res)
        if stop.requested:
            farm.client.cancel(list(futures))
            break
        progress.draw()
        time.sleep(_POLL)
    timing["write_s_mean"] = statistics.fmean(write_s) if write_s else 0.0


def _create_folder(out, wedge):
    try:
        record.create_folder(out, wedge)
    except OSError as e:
        raise OutputFailure(f"--out: cannot write to {out}: {e.strerror or e}") from None


def _record(out, wedge, variant, res, rows, progress):
    thumb = res.pop("thumbnail", None)
    if thumb:
        record.save_thumb(out, variant.id, thumb)
    rows[variant.id] = record.index_row(wedge, variant, res)
    _write_index(out, wedge, rows)
    progress.finished(variant.id, res["status"] == "ok", int(res.get("frames") or 0))


def _write_index(out, wedge, rows):
    try:
        record.write_index(out, wedge, [rows[v.id] for v in wedge.variants])
    except OSError as e:
        raise OutputFailure(f"--out: cannot write {record.INDEX} in {out}: {e.strerror or e}") from None


def _sheet(out, wedge, rows):
    try:
        return build_sheet(out, wedge, rows)
    except OSError as e:
        raise OutputFailure(f"--out: cannot write {record.SHEET} in {out}: {e.strerror or e}") from None


def _save_record(out, wedge, timing):
    try:
        record.write_record(out, wedge, {k: round(v, 4) if isinstance(v, float) else v
                                         for k, v in timing.items()})
    except OSError as e:
        raise OutputFailure(f"--out: cannot write {record.RECORD} in {out}: {e.strerror or e}") from None


def _overhead(results, timing) -> dict:
    """Where the workers' time went. ``busy``: worker time inside variants (scene build, kernels,
    frames, thumbnail), not counting Taichi's program start and reset around each (``taichi_s``,
    with the imports on a worker's first variant). ``tail``: workers idle at the end, waiting for
    the last variant elsewhere (uneven variants, not a cost of the farm). The rest of workers ×
    wall, per variant, is the overhead: cluster start, Taichi's imports, start and reset,
    scheduling gaps between a worker's variants, the contact sheet. Each worker's figures use its
    own clock. ``cpu_s``: CPU seconds of the workers (to their last variant) and of this process
    (with a local cluster, its scheduler), whatever else the machine was running. ``compile_s``:
    Taichi's compile time (kernels not found in the offline cache)."""
    ran = [r for r in results if "t_start" in r]
    if not ran or not timing.get("workers"):
        return {}
    busy = sum(r["t_end"] - r["t_start"] - r.get("init_s", 0.0) for r in ran)
    spans = defaultdict(list)
    for r in ran:
        spans[r["worker"]].append((r["t_start"], r["t_end"]))
    gaps = [b[0] - a[1] for s in spans.values() for a, b in zip(sorted(s), sorted(s)[1:])]
    last = max(r["t_end"] for r in ran)
    tail = sum(last - max(end for _, end in s) for s in spans.values())
    cpu = {}  # worker -> its process CPU seconds at its last variant
    for r in ran:
        cpu[r["worker"]] = max(cpu.get(r["worker"], 0.0), r.get("process_cpu_s", 0.0))
    return {"busy_s": busy, "tail_idle_s": tail,
            "overhead_per_variant_s": (timing["workers"] * timing["wall_s"] - busy - tail) / len(ran),
            "gap_s_mean": statistics.fmean(gaps) if gaps else 0.0,
            "taichi_s_mean": statistics.fmean(r.get("init_s", 0.0) for r in ran),
            "compile_s": sum(r.get("compile_s", 0.0) for r in ran),
            "cpu_s": sum(cpu.values()) + time.process_time()}  # workers + this process


def _summary(wedge, out, rows, sheet, timing, stopped) -> int:
    failed = [(vid, r) for vid, r in rows.items() if r["status"] not in ("ok", "pending")]
    ok = sum(r["status"] == "ok" for r in rows.values())
    ov = timing.get("overhead_per_variant_s")
    where = (f"{timing['workers']} worker(s) x {timing['threads_per_worker'] or 'all'} thread(s)"
             if timing.get("workers") else "nothing to render")
    print(f"{wedge.name}: {len(wedge.variants)} variants ({ok} ok, {len(failed)} failed"
          + (f", {timing['skipped']} already done" if timing["skipped"] else "")
          + f") in {out}: {record.INDEX}, {os.path.basename(sheet)}; {timing['wall_s']:.1f} s wall on "
          + where + (f"; overhead {ov:.2f} s per variant" if ov is not None else ""))
    if stopped is not None:
        raise Stopped(f"stopped by {stopped.name}: {ok} of {len(wedge.variants)} variants done "
                      f"(index in {out}); continue with --resume", stopped.signum)
    if failed:
        labels = {v.id: v.label(wedge.keys) for v in wedge.variants}
        lines = [f"variant {vid} ({labels[vid]}): exit {r['exit_code']}: {r['message']}"
                 for vid, r in failed[:10]]
        if len(failed) > 10:
            lines.append(f"... and {len(failed) - 10} more failed variants (see {record.INDEX})")
        e = UserError("\n".join(lines))
        e.exit_code = int(failed[0][1]["exit_code"] or 1)
        raise e
    return 0
