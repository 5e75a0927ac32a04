// Flamenco 3 job type: one radiosity bake whose hemicube calls run on the farm's machines.
//
// Put this file in the `scripts` folder next to `flamenco-manager` (docs/farm.md). A job starts
// a Dask scheduler, `workers` Dask workers and the bake on Flamenco workers at once; they meet
// through a scheduler file on shared storage. The bake (Blender in the background, the batch
// script with --scheduler) cuts every hemicube call into one part per Dask worker and puts the
// parts back in order: the result is bit-identical to a bake on one machine. A last task stops
// the scheduler, and the Dask workers with it. Needs as many free Flamenco workers as
// `workers` + 2 (the scheduler and the bake wait for the Dask workers for `wait_seconds`).

const JOB_TYPE = {
    label: "Radiosity Bake (Dask)",
    settings: [
        { key: "blendfile", type: "string", required: true, subtype: "file_path",
          description: "The .blend to bake (on shared storage)" },
        { key: "output", type: "string", required: true, subtype: "file_path",
          description: "Where to save the baked .blend" },
        { key: "repository", type: "string", required: true, subtype: "dir_path",
          description: "The Radiosity Baker repository (on shared storage)" },
        { key: "python", type: "string", default: "python3",
          description: "A Python with NumPy and dask[distributed] on every worker" },
        { key: "workers", type: "int32", default: 4, description: "Dask workers" },
        { key: "wait_seconds", type: "int32", default: 120,
          description: "How long the bake waits for the scheduler" },
        { key: "extra_args", type: "string", default: "",
          description: "More batch options, e.g. --report /shared/report.json" },
    ]
};

function compileJob(job) {
    const s = job.settings;
    const dir = s.output + ".dask";
    const schedulerFile = dir + "/scheduler.json";
    const env = "PYTHONPATH=" + s.repository;

    const scheduler = author.Task("dask-scheduler", "misc");
    scheduler.addCommand(author.Command("exec", {
        exe: "env",
        args: [env, s.python, "-m", "distributed.cli.dask_scheduler",
               "--scheduler-file", schedulerFile, "--idle-timeout", "3600"],
    }));
    job.addTask(scheduler);

    for (let i = 0; i < s.workers; i++) {
        const worker = author.Task("dask-worker-" + i, "misc");
        worker.addCommand(author.Command("exec", {
            exe: "env",
            args: [env, s.python, "-m", "distributed.cli.dask_worker",
                   "--scheduler-file", schedulerFile, "--nthreads", "1",
                   "--death-timeout", String(s.wait_seconds)],
        }));
        job.addTask(worker);
    }

    const bake = author.Task("bake", "blender");
    const extra = s.extra_args ? s.extra_args.split(" ") : [];
    bake.addCommand(author.Command("blender-render", {
        exe: "{blender}",
        exeArgs: "{blenderArgs}",
        argsBefore: [],
        blendfile: s.blendfile,
        args: ["--python", s.repository + "/radiosity_addon/batch.py", "--",
               s.blendfile, "--output", s.output, "--scheduler", schedulerFile,
               "--scheduler-wait", String(s.wait_seconds)].concat(extra),
    }));
    job.addTask(bake);

    const stop = author.Task("stop-dask", "misc");
    stop.addCommand(author.Command("exec", {
        exe: s.python,
        args: ["-c", "from distributed import Client; " +
               "Client(scheduler_file='" + schedulerFile + "').shutdown()"],
    }));
    stop.addDependency(bake);
    job.addTask(stop);
}
