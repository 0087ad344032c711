#!/usr/bin/env bash
# The URI of the Debian main archive this machine's apt is already configured with, so that
# bookworm-backports comes from the same mirror or proxy (labs and CI often reach Debian only
# through their own). Reads deb822 files (*.sources) and classic one-line files (*.list), skipping
# the security and updates archives and third-party repositories.
#
#   debian_main_uri [SOURCES_DIR] [SOURCES_LIST]   # prints the URI, or returns 1 when none is found
#
# Usage: `. tools/debian_mirror.sh; uri=$(debian_main_uri)`; or run this file to print it.

# A deb822 stanza or classic line is Debian's main archive when its suites include the release
# codename itself (not -security/-updates/-backports) and its components include "main". The URI
# may be any host or path: mirrors, proxies (apt-cacher), file:// and snapshot archives all qualify.
debian_main_uri() {
    local dir="${1:-/etc/apt/sources.list.d}" list="${2:-/etc/apt/sources.list}"
    local codename="${DEBIAN_CODENAME:-bookworm}" f uri
    for f in "$dir"/*.sources; do
        [ -f "$f" ] || continue
        uri=$(awk -v want="$codename" '
            function flush() {
                if (types ~ /(^| )deb( |$)/ && suites ~ ("(^| )" want "( |$)") && comps ~ /(^| )main( |$)/ && enabled != "no" && uris != "")
                    { split(uris, u, " "); print u[1]; found = 1; exit }
                types = uris = suites = comps = ""; enabled = "yes"
            }
            BEGIN { enabled = "yes" }
            /^[ \t]*#/ { next }
            /^[ \t]*$/ { flush(); next }
            {
                key = tolower($1); sub(/:$/, "", key); $1 = ""; sub(/^[ \t]+/, "")
                if (key == "types") types = $0
                else if (key == "uris") uris = $0
                else if (key == "suites") suites = $0
                else if (key == "components") comps = $0
                else if (key == "enabled") enabled = tolower($0)
            }
            END { if (!found) flush() }
        ' "$f")
        if [ -n "$uri" ]; then echo "$uri"; return 0; fi
    done
    for f in "$list" "$dir"/*.list; do
        [ -f "$f" ] || continue
        # deb [option=value ...] URI SUITE COMPONENT...
        uri=$(awk -v want="$codename" '
            /^[ \t]*#/ || $1 != "deb" { next }
            {
                i = 2
                if ($i ~ /^\[/) { while (i <= NF && $i !~ /\]$/) i++; i++ }
                if (i + 2 > NF) next
                uri = $i; suite = $(i + 1); main = 0
                for (j = i + 2; j <= NF; j++) if ($j == "main") main = 1
                if (suite == want && main) { print uri; exit }
            }
        ' "$f")
        if [ -n "$uri" ]; then echo "$uri"; return 0; fi
    done
    return 1
}

if [ "${BASH_SOURCE[0]}" = "$0" ]; then
    debian_main_uri "$@"
fi
