#!/usr/bin/python3
"""ctest `data_robomimic_h5py` (label `data`): our HDF5 files as robomimic reads them, and
robomimic's files (with images) as `secure demos convert` reads them.

robomimic is not installed here; its readers are mirrored with h5py (Debian's python3-h5py), the
calls and checks as robomimic 0.3 makes them:
- `FileUtils.get_env_metadata_from_dataset`: json.loads(f["data"].attrs["env_args"]);
- `FileUtils.get_shape_metadata_from_dataset`: the first key of f["data"], its
  actions.shape[1], obs/<key>.shape[1:] for every key;
- `SequenceDataset.load_demo_info`: the demos of data/ or of a filter key mask/<key> (byte
  strings, decoded as UTF-8), sorted by int(name[5:]), each demo's attrs["num_samples"];
- `SequenceDataset.load_dataset_in_memory`: obs/<key> and next_obs/<key> with [()], and
  actions, rewards, dones with [()].astype("float32"), the file opened with swmr=True,
  libver="latest" as SequenceDataset opens it;
- `scripts/split_train_val.py`: mask/train and mask/valid hold every demo once.
Then a robomimic-style file written with h5py (uint8 images beside low-dimensional keys, gzip
as robomimic's scripts write) is converted with `--obs-keys`, and selecting the image is a
one-line error naming the file, the dataset and the dtype. Environment: SECURE_CLI (the binary),
SECURE_WORK (a scratch directory).
"""
import csv
import json
import os
import shutil
import subprocess
import sys

import h5py
import numpy as np

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
from script_checks import check, exit_status  # noqa: E402

CLI = os.environ["SECURE_CLI"]
WORK = os.environ["SECURE_WORK"]


def run(*args):
    return subprocess.run([CLI, *args], capture_output=True, text=True, timeout=120)


def write_demos_csv(path, lengths):
    """Demonstrations with a 3-column key, a 2-column key and a scalar; values encode
    (episode, step, column) so every read can be checked exactly."""
    columns = ["robot0_eef_pos[0]", "robot0_eef_pos[1]", "robot0_eef_pos[2]",
               "object[0]", "object[1]", "gripper"]
    rows = []
    for e, n in enumerate(lengths):
        for t in range(n):
            obs = [100 * e + t + 0.125 * j for j in range(len(columns))]
            act = [-(100 * e + t) - 0.5 * j for j in range(2)]
            rows.append([e, t] + obs + act)
    with open(path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["episode", "step"] + columns + ["a0", "a1"])
        w.writerows(rows)
    return columns, rows


def our_file_as_robomimic_reads_it():
    lengths = [5, 3, 4, 6, 2, 3, 3, 4, 5, 2, 7, 3]  # 12 demos: demo_9 is the validation demo
    csv_path = os.path.join(WORK, "demos.csv")
    h5_path = os.path.join(WORK, "demos.hdf5")
    write_demos_csv(csv_path, lengths)
    r = run("demos", "convert", csv_path, h5_path, "--action-features", "a0,a1")
    if not check(r.returncode == 0, "demos convert to HDF5 failed: " + r.stderr):
        return
    total = sum(lengths)

    # FileUtils.get_env_metadata_from_dataset / get_shape_metadata_from_dataset.
    with h5py.File(h5_path, "r") as f:
        env_meta = json.loads(f["data"].attrs["env_args"])
        check(set(env_meta) >= {"env_name", "type", "env_kwargs"}, "env_args: %r" % env_meta)
        check(isinstance(env_meta["env_kwargs"], dict), "env_kwargs is not a dict")
        demo_id = list(f["data"].keys())[0]
        demo = f["data/{}".format(demo_id)]
        check(f["data/{}/actions".format(demo_id)].shape[1] == 2, "ac_dim")
        shapes = {k: demo["obs/{}".format(k)].shape[1:] for k in sorted(demo["obs"])}
        check(shapes == {"gripper": (1,), "object": (2,), "robot0_eef_pos": (3,)},
              "obs shapes %r" % shapes)
        check(int(f["data"].attrs["total"]) == total, "data.attrs['total']")
        check(sorted(f.keys()) == ["data", "mask"], "top-level groups %r" % list(f.keys()))

    # SequenceDataset, opened as it opens the file.
    f = h5py.File(h5_path, "r", swmr=True, libver="latest", rdcc_nbytes=int(1e10))

    def load_demo_info(filter_by_attribute=None):
        if filter_by_attribute is not None:
            demos = [elem.decode("utf-8")
                     for elem in np.array(f["mask/{}".format(filter_by_attribute)][:])]
        else:
            demos = list(f["data"].keys())
        inds = np.argsort([int(elem[5:]) for elem in demos])
        demos = [demos[i] for i in inds]
        lengths = {ep: f["data/{}".format(ep)].attrs["num_samples"] for ep in demos}
        return demos, lengths

    all_demos, all_lengths = load_demo_info()
    check(all_demos == ["demo_%d" % i for i in range(len(lengths))], "demos %r" % all_demos)
    check([int(all_lengths[d]) for d in all_demos] == lengths, "num_samples")
    train, _ = load_demo_info("train")
    valid, _ = load_demo_info("valid")
    check(valid == ["demo_9"], "mask/valid %r" % valid)
    check(sorted(train + valid, key=lambda d: int(d[5:])) == all_demos and
          not set(train) & set(valid), "mask/train and mask/valid do not partition the demos")
    check(f["mask/train"].dtype.kind == "S", "mask/train dtype %r" % f["mask/train"].dtype)

    obs_keys = ("robot0_eef_pos", "object", "gripper")
    dataset_keys = ("actions", "rewards", "dones")
    for e, ep in enumerate(all_demos):
        n = int(all_lengths[ep])
        obs = {k: f["data/{}/obs/{}".format(ep, k)][()] for k in obs_keys}
        next_obs = {k: f["data/{}/next_obs/{}".format(ep, k)][()] for k in obs_keys}
        data = {k: f["data/{}/{}".format(ep, k)][()].astype("float32") for k in dataset_keys}
        t = np.arange(n, dtype=np.float64)[:, None]
        expected_pos = 100 * e + t + 0.125 * np.arange(3)
        check(obs["robot0_eef_pos"].dtype == np.float64, "obs dtype")
        check(np.array_equal(obs["robot0_eef_pos"], expected_pos), ep + ": obs/robot0_eef_pos")
        check(np.array_equal(obs["gripper"], 100 * e + t + 0.625), ep + ": obs/gripper")
        for k in obs_keys:
            check(next_obs[k].shape == obs[k].shape, ep + ": next_obs/" + k + " shape")
            check(np.array_equal(next_obs[k][:-1], obs[k][1:]), ep + ": next_obs/" + k)
            check(np.array_equal(next_obs[k][-1], obs[k][-1]), ep + ": last next_obs/" + k)
        check(data["actions"].shape == (n, 2), ep + ": actions shape")
        check(np.array_equal(data["actions"][:, 1], -(100 * e + np.arange(n)) - 0.5),
              ep + ": actions")
        check(data["rewards"].shape == (n,) and not data["rewards"].any(), ep + ": rewards")
        check(data["dones"].shape == (n,) and data["dones"][-1] == 1 and
              data["dones"].sum() == 1, ep + ": dones")
        check(f["data/{}".format(ep)]["states"].shape == (n, 6), ep + ": states")
    f.close()

    # And back: our reader ignores next_obs and mask/; CSV -> HDF5 -> CSV keeps every value.
    back = os.path.join(WORK, "back.csv")
    r = run("demos", "convert", h5_path, back)
    if check(r.returncode == 0, "demos convert back to CSV failed: " + r.stderr):
        def table(p):
            with open(p) as f:
                rows = list(csv.reader(f))
            return rows[0], [[float(x) for x in row] for row in rows[1:]]
        check(table(back) == table(csv_path), "CSV -> HDF5 -> CSV changed the data")


def robomimic_file_with_images_converts():
    path = os.path.join(WORK, "foreign.hdf5")
    lengths = [4, 6, 3]
    rng = np.random.default_rng(0)
    with h5py.File(path, "w") as f:
        data = f.create_group("data")
        data.attrs["total"] = sum(lengths)
        data.attrs["env_args"] = json.dumps({"env_name": "Lift", "type": 1, "env_kwargs": {}})
        for i, n in enumerate(lengths):
            ep = data.create_group("demo_%d" % i)
            ep.attrs["num_samples"] = n
            ep.attrs["model_file"] = "<mujoco/>"
            for group in ("obs", "next_obs"):
                g = ep.create_group(group)
                g.create_dataset("agentview_image", compression="gzip",
                                 data=rng.integers(0, 255, (n, 84, 84, 3), dtype=np.uint8))
                g.create_dataset("robot0_eef_pos", data=i * 10 + np.arange(3 * n).reshape(n, 3)
                                 .astype(np.float64))
                g.create_dataset("object", data=np.zeros((n, 10)))
            ep.create_dataset("actions", data=np.full((n, 7), float(i), dtype=np.float64))
            ep.create_dataset("rewards", data=np.zeros(n))
            ep.create_dataset("dones", data=np.eye(1, n, n - 1, dtype=np.int64)[0])
            ep.create_dataset("states", data=np.zeros((n, 45)))
        f["mask/train"] = np.array(["demo_0", "demo_1"], dtype="S")
        f["mask/valid"] = np.array(["demo_2"], dtype="S")

    # The command of apps/secure/README.md: the low-dimensional key only.
    out = os.path.join(WORK, "f.csv")
    r = run("demos", "convert", path, out, "--obs-keys", "robot0_eef_pos")
    if check(r.returncode == 0, "convert --obs-keys robot0_eef_pos failed: " + r.stderr):
        with open(out) as f:
            rows = list(csv.reader(f))
        check(rows[0] == ["episode", "step", "robot0_eef_pos[0]", "robot0_eef_pos[1]",
                          "robot0_eef_pos[2]"] + ["actions[%d]" % j for j in range(7)],
              "header %r" % rows[0])
        check(len(rows) == 1 + sum(lengths), "rows")
        check(rows[1 + 4 + 1][:5] == ["1", "1", "13", "14", "15"], "demo_1 step 1: %r"
              % rows[6][:5])
    # HDF5 to HDF5 keeps the selected key only, and robomimic reads the result.
    out_h5 = os.path.join(WORK, "f.h5")
    r = run("demos", "convert", path, out_h5, "--obs-keys", "robot0_eef_pos,object", "--json")
    if check(r.returncode == 0, "convert to HDF5 failed: " + r.stderr):
        doc = json.loads(r.stdout)
        check(doc["demonstrations"] == 3 and doc["steps"] == sum(lengths), "--json counts")
        with h5py.File(out_h5, "r") as f:
            check(sorted(f["data/demo_1/obs"].keys()) == ["object", "robot0_eef_pos"],
                  "keys %r" % list(f["data/demo_1/obs"].keys()))
            check(f["data/demo_1/next_obs/object"].shape == (6, 10), "next_obs/object shape")
    # Selecting the image, or nothing: one line naming the file, the dataset and the dtype.
    for extra in (["--obs-keys", "robot0_eef_pos,agentview_image"], []):
        r = run("demos", "convert", path, os.path.join(WORK, "g.csv"), *extra)
        err = r.stderr.strip()
        check(r.returncode == 1, "image selected %r: exit %d" % (extra, r.returncode))
        check("\n" not in err, "not one line: %r" % err)
        for part in (path, "data/demo_0/obs/agentview_image", "uint8", "(4, 84, 84, 3)"):
            check(part in err, "error %r lacks %r" % (err, part))
        if not extra:
            check("select the others by name (object, robot0_eef_pos)" in err,
                  "error %r does not name the keys to select" % err)
        check(not os.path.exists(os.path.join(WORK, "g.csv")), "a failed convert wrote a file")


def main():
    shutil.rmtree(WORK, ignore_errors=True)
    os.makedirs(WORK)
    our_file_as_robomimic_reads_it()
    robomimic_file_with_images_converts()
    status = exit_status("robomimic h5py checks passed")
    if status == 0:
        shutil.rmtree(WORK, ignore_errors=True)
    return status


if __name__ == "__main__":
    sys.exit(main())
