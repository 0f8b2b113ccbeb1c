#!/usr/bin/python3
"""ctest `docs_domain_rows` (label `report`): the documentation's tables of domains are true to
the registry. `secure domains --json` (and `secure domains NAME --json` for each one's config
section) says which domains are registered; then:

- domains/README.md: a row `| \\`<folder>/\\` | \\`<name>\\` | ...` for every registered domain, and
  no row naming a domain that is not registered;
- configs/README.md: a row `| \\`<section>:\\` | the <name> domain's experiment section ...` for
  every registered domain (its Domain::ConfigSection), and none for another;
- docs/ARCHITECTURE.md: a plug-in row `| \\`domains/<folder>/\\` (root) | ... | plug-in: ...` for
  every registered domain's folder (the folder of its domains/README.md row), and none for a
  folder that holds no registered domain.

A plug-in outside `domains/` (examples/toy_domain, added by one `add_subdirectory` line) is not a
row of these tables: it is documented in its own folder, so the checks cover the registered
domains whose folder `domains/<name with _ for ->/` exists.

The checker is also run on copies with a row removed and with a row added, and must fail on
each (so the checks above can fail). Environment: SECURE_CLI (the binary), SECURE_SOURCE_DIR.
"""
import json
import os
import re
import subprocess
import sys

CLI = os.environ["SECURE_CLI"]
SOURCE = os.environ["SECURE_SOURCE_DIR"]
DOCS = {"readme": "domains/README.md", "configs": "configs/README.md",
        "architecture": "docs/ARCHITECTURE.md"}

README_ROW = re.compile(r"^\| `([a-z0-9_]+)/` \| `([a-z0-9-]+)` \|", re.M)
CONFIGS_ROW = re.compile(r"^\| `([a-z0-9_]+):` \| the ([a-z0-9-]+) domain's experiment section",
                         re.M)
ARCHITECTURE_ROW = re.compile(r"^\| `domains/([a-z0-9_]+)/` \(root\) \| [^|]* \| plug-in:", re.M)


def cli_json(*args):
    r = subprocess.run([CLI, *args, "--json"], capture_output=True, text=True, timeout=120)
    if r.returncode != 0:
        sys.exit("FAIL: secure %s --json: %s" % (" ".join(args), r.stderr.strip()))
    return json.loads(r.stdout)


def registry():
    """{registered name: its config section}."""
    names = [d["name"] for d in cli_json("domains")["domains"]]
    return {n: cli_json("domains", n)["config_section"] for n in names}


def problems(domains, texts):
    """What the documents get wrong about `domains` ({name: section}), as messages."""
    out = []
    folders = {}  # registry name -> folder, from domains/README.md
    for folder, name in README_ROW.findall(texts["readme"]):
        if name not in domains:
            out.append("%s: the row of `%s/` names '%s', which is not a registered domain"
                       % (DOCS["readme"], folder, name))
        folders[name] = folder
    for name in domains:
        if name not in folders:
            out.append("%s: no row for the registered domain '%s'" % (DOCS["readme"], name))
    sections = {}
    for section, name in CONFIGS_ROW.findall(texts["configs"]):
        if domains.get(name) != section:
            out.append("%s: the row `%s:` is the experiment section of '%s', whose section is %s"
                       % (DOCS["configs"], section, name,
                          "'%s'" % domains[name] if name in domains else "none (not registered)"))
        sections[name] = section
    for name, section in domains.items():
        if name not in sections:
            out.append("%s: no row `%s:` for the registered domain '%s'"
                       % (DOCS["configs"], section, name))
    plugins = set(ARCHITECTURE_ROW.findall(texts["architecture"]))
    for name in domains:  # a domain without a README row: its folder by the convention
        folder = folders.get(name, name.replace("-", "_"))
        if folder not in plugins:
            out.append("%s: no plug-in row for `domains/%s/` (the domain '%s')"
                       % (DOCS["architecture"], folder, name))
    for folder in plugins - set(folders.values()):
        out.append("%s: the plug-in row `domains/%s/` holds no registered domain"
                   % (DOCS["architecture"], folder))
    return out


def main():
    registered = registry()
    domains = {n: s for n, s in registered.items()
               if os.path.isdir(os.path.join(SOURCE, "domains", n.replace("-", "_")))}
    outside = sorted(set(registered) - set(domains))
    texts = {}
    for key, rel in DOCS.items():
        with open(os.path.join(SOURCE, rel), encoding="utf-8") as f:
            texts[key] = f.read()
    failures = problems(domains, texts)
    for p in failures:
        print("FAIL: " + p, file=sys.stderr)
    if len(domains) < 2:
        failures.append("the registry lists %d domains" % len(domains))
        print("FAIL: " + failures[-1], file=sys.stderr)

    # The checker fails on a row removed from, and on a row added to, each document.
    added = {"readme": "| `nowhere/` | `no-such-domain` | x |\n",
             "configs": "| `nowhere:` | the no-such-domain domain's experiment section | x |\n",
             "architecture": "| `domains/nowhere/` (root) | `secure::x` | plug-in: x | no |\n"}
    for key, rx in (("readme", README_ROW), ("configs", CONFIGS_ROW),
                    ("architecture", ARCHITECTURE_ROW)):
        rows = [m for m in rx.finditer(texts[key])]
        if not rows:
            failures.append("%s: no row of domains found" % DOCS[key])
            print("FAIL: " + failures[-1], file=sys.stderr)
            continue
        row = rows[0]
        end = texts[key].index("\n", row.start()) + 1
        for what, text in (("removed", texts[key][:row.start()] + texts[key][end:]),
                           ("added", texts[key] + "\n" + added[key])):
            if not problems(domains, dict(texts, **{key: text})):
                failures.append("the checker does not notice a row %s in %s" % (what, DOCS[key]))
                print("FAIL: " + failures[-1], file=sys.stderr)
    print("docs rows: %d registered domains (%s) checked in %s; %d problems%s"
          % (len(domains), ", ".join(sorted(domains)), ", ".join(DOCS.values()), len(failures),
             "; outside domains/ (documented in their own folders): " + ", ".join(outside)
             if outside else ""))
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
