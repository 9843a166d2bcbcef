"""Reads a Debian Packages index on stdin and prints the pool file and SHA256 of each named
package and of everything it depends on (first alternative, virtual packages through Provides),
skipping what only an installed system needs (dpkg, debconf and the like):
scripts/lavapipe-coop/run unpacks them into a directory instead of installing them."""

import re
import sys

SYSTEM_ONLY = {
    "base-files", "debconf", "debconf-2.0", "dpkg", "install-info", "libc-bin",
    "perl-base", "sensible-utils", "tzdata",
}


def field(stanza, name):
    m = re.search(rf"^{name}: (.*)$", stanza, re.M)
    return m.group(1) if m else ""


def main():
    packages, provided = {}, {}
    for stanza in sys.stdin.read().split("\n\n"):
        name = field(stanza, "Package")
        if not name or name in packages:
            continue
        packages[name] = (
            field(stanza, "Filename") + " " + field(stanza, "SHA256"),
            field(stanza, "Pre-Depends") + "," + field(stanza, "Depends"),
        )
        for p in field(stanza, "Provides").split(","):
            virtual = p.strip().split(" ")[0]
            if virtual:
                provided.setdefault(virtual, name)
    wanted, order = set(), []

    def add(name):
        name = name if name in packages else provided.get(name, name)
        if name in wanted or name in SYSTEM_ONLY:
            return
        if name not in packages:
            sys.exit(f"resolve.py: no package {name} in the index")
        wanted.add(name)
        order.append(name)
        for dep in packages[name][1].split(","):
            first = dep.split("|")[0].strip().split(" ")[0].split(":")[0]
            if first:
                add(first)

    for name in sys.argv[1:]:
        add(name)
    for name in order:
        print(packages[name][0])


if __name__ == "__main__":
    main()
