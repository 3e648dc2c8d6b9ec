#!/usr/bin/env python3
"""Fetches the real-camera raw corpus listed in scripts/corpus/manifest.json.

    python3 scripts/corpus/fetch_raw_corpus.py [--dir DIR]

The files are test data of Debian source packages (ExifTool, Exiv2, Tracker Miners,
KImageFormats). Each package's upstream tarball is downloaded with `apt-get source
--download-only` under a private apt configuration (its own lists and cache in DIR/_apt, with
`deb-src` entries made from this machine's configured `deb` entries), so the system's apt setup
is not changed and no root is needed beyond reading it. The named members are extracted into
DIR (default: target/raw-corpus/ at the repository root, or $SKINBRDF_RAW_CORPUS) and each is
checked against the manifest's size and sha256.

Idempotent: a file already present with the right sha256 is kept, and a tarball already in
DIR/_sources is not downloaded again. Offline: a download that fails stops with a message
naming the package, exit status 2; files fetched before stay. On success DIR/.fetched holds the
manifest's sha256 (the test over the fetched corpus reads it to know the script was run).
A file whose content does not match the manifest is an error (exit status 1).
"""
import argparse
import glob
import hashlib
import json
import os
import re
import shutil
import subprocess
import sys
import tarfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
MANIFEST = Path(__file__).resolve().parent / "manifest.json"


def sha256(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for chunk in iter(lambda: f.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def deb_src_lines() -> list[str]:
    """`deb-src` lines for every `deb` entry of this machine's apt sources (one-line and deb822)."""
    lines = []
    for path in ["/etc/apt/sources.list", *sorted(glob.glob("/etc/apt/sources.list.d/*.list"))]:
        if not os.path.exists(path):
            continue
        for line in open(path, encoding="utf-8", errors="replace"):
            line = line.split("#", 1)[0].strip()
            if line.startswith("deb "):
                lines.append("deb-src " + line[4:])
    for path in sorted(glob.glob("/etc/apt/sources.list.d/*.sources")):
        text = open(path, encoding="utf-8", errors="replace").read()
        for stanza in re.split(r"\n\s*\n", text):
            fields = {}
            for line in stanza.splitlines():
                if line.startswith("#") or ":" not in line or line[:1].isspace():
                    continue
                key, value = line.split(":", 1)
                fields[key.strip().lower()] = value.strip()
            if "deb" not in fields.get("types", "").split() or fields.get("enabled", "yes") == "no":
                continue
            opts = f"[signed-by={fields['signed-by']}] " if "signed-by" in fields else ""
            for uri in fields.get("uris", "").split():
                for suite in fields.get("suites", "").split():
                    lines.append(f"deb-src {opts}{uri} {suite} {fields.get('components', '')}".rstrip())
    return lines


class Apt:
    """apt-get with its own source list, lists and cache under `base`."""

    def __init__(self, base: Path):
        self.base = base
        self.updated = False

    def opts(self) -> list[str]:
        b = self.base
        return [
            "-o", f"Dir::Etc::SourceList={b / 'sources.list'}",
            "-o", "Dir::Etc::SourceParts=/dev/null",
            "-o", f"Dir::State::Lists={b / 'lists'}",
            "-o", f"Dir::Cache={b / 'cache'}",
            "-o", "APT::Sandbox::User=root",
            "-q",
        ]

    def update(self):
        if self.updated:
            return
        (self.base / "lists" / "partial").mkdir(parents=True, exist_ok=True)
        (self.base / "cache" / "archives" / "partial").mkdir(parents=True, exist_ok=True)
        lines = deb_src_lines()
        if not lines:
            raise FetchError("this machine's apt configuration has no 'deb' entries to make 'deb-src' entries from")
        (self.base / "sources.list").write_text("\n".join(lines) + "\n")
        r = subprocess.run(["apt-get", *self.opts(), "update"], capture_output=True, text=True)
        if r.returncode != 0 or re.search(r"^(W|E): Failed to fetch", r.stdout + r.stderr, re.M):
            raise FetchError(
                "apt-get update of the source indexes failed (no network, or no package mirror reachable):\n"
                + (r.stderr or r.stdout).strip()
            )
        self.updated = True

    def source(self, package: str, version: str, into: Path):
        """Downloads `package`'s source (that version, else the current one) into `into`."""
        self.update()
        into.mkdir(parents=True, exist_ok=True)
        for spec in (f"{package}={version}", package):
            r = subprocess.run(
                ["apt-get", *self.opts(), "source", "--download-only", spec],
                cwd=into, capture_output=True, text=True,
            )
            if r.returncode == 0:
                return
        raise FetchError(f"apt-get source {package} failed:\n{(r.stderr or r.stdout).strip()}")


class FetchError(Exception):
    pass


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--dir", type=Path, default=None,
                    help="cache directory (default $SKINBRDF_RAW_CORPUS or target/raw-corpus)")
    args = ap.parse_args()
    out = args.dir or Path(os.environ.get("SKINBRDF_RAW_CORPUS", ROOT / "target" / "raw-corpus"))
    out.mkdir(parents=True, exist_ok=True)
    manifest = json.loads(MANIFEST.read_text())
    sources_dir = out / "_sources"
    apt = Apt(out / "_apt")
    bad = []
    fetched = kept = 0
    try:
        for source, files in group_by_source(manifest["files"]).items():
            missing = [f for f in files if not ok(out / f["file"], f)]
            kept += len(files) - len(missing)
            if not missing:
                continue
            src = manifest["sources"][source]
            tarball = sources_dir / src["orig"]
            if not tarball.exists():
                print(f"downloading the source of {source} {src['version']} ...", flush=True)
                apt.source(source, src["version"], sources_dir)
                if not tarball.exists():
                    raise FetchError(f"apt-get source {source} gave no {src['orig']} (another upstream version?)")
            extract(tarball, src["prefix"], missing, out)
            for f in missing:
                if ok(out / f["file"], f):
                    fetched += 1
                else:
                    bad.append(f["file"])
    except FetchError as e:
        print(f"fetch_raw_corpus: {e}", file=sys.stderr)
        print(f"fetch_raw_corpus: nothing more fetched; {kept} files were already in {out}", file=sys.stderr)
        return 2
    if bad:
        print(f"fetch_raw_corpus: content differs from the manifest (size or sha256): {', '.join(bad)}", file=sys.stderr)
        return 1
    (out / ".fetched").write_text(sha256(MANIFEST) + "\n")
    print(f"{len(manifest['files'])} files in {out} ({fetched} fetched, {kept} already there), sha256 verified")
    return 0


def group_by_source(files: list[dict]) -> dict[str, list[dict]]:
    groups: dict[str, list[dict]] = {}
    for f in files:
        groups.setdefault(f["source"], []).append(f)
    return groups


def ok(path: Path, entry: dict) -> bool:
    return path.is_file() and path.stat().st_size == entry["size"] and sha256(path) == entry["sha256"]


def extract(tarball: Path, prefix: str, files: list[dict], out: Path):
    wanted = {prefix + f["file"]: f["file"] for f in files}
    with tarfile.open(tarball) as tar:
        for member in tar:
            name = wanted.get(member.name)
            if name is None or not member.isfile():
                continue
            src = tar.extractfile(member)
            if src is None:
                continue
            tmp = out / (name + ".part")
            with open(tmp, "wb") as dst:
                shutil.copyfileobj(src, dst)
            tmp.replace(out / name)


if __name__ == "__main__":
    sys.exit(main())
