#!/usr/bin/env bash
# Fetch free-licensed photographs from Debian's wallpaper packages, for
# training denoisers on natural images "unprocessed" into RAW space.
#
# Usage: tools/fetch_photos.sh [--allow-drift] [DEST]
#   DEST defaults to $HOME/.cache/pgrf/photos. DEST must not lie inside this
#   repository: photos are never committed.
#
# The script is deterministic: which files are kept was decided once, by
# looking at every image and reading each package's debian/copyright and
# metadata; that decision is the ALLOW list below. tools/photos.tsv records,
# for each kept file, the package version it was taken from, author, licence,
# size and SHA-256. Every fetched file is checked against that SHA-256; a
# package that moved to another version is reported, and a file whose hash
# differs is not copied (the run fails) unless --allow-drift is given.
#
# Needs: apt-get (with Debian/Ubuntu package lists: run 'apt-get update' once
# on a fresh system), dpkg-deb, sha256sum, awk, realpath. No root needed:
# 'apt-get download' only fetches .deb files into a temporary folder, and
# nothing is installed.
#
# Examined (Debian 12 "bookworm"), and why files were kept or left out:
#   mate-backgrounds 1.26.0-1            keep nature/*.jpg (12 photos, GPL-2+).
#       Rejected: abstract/* (rendered; Elephants*.jpg is a painting),
#       desktop/* (rendered: stripes, logo, Ubuntu-Mate-*-no-logo aurora art).
#   plasma-workspace-wallpapers 4:5.27.5-2  keep 10 photographic wallpapers
#       (authors from metadata.json). Left out Grey (a grey-scale photo: no
#       colour to unprocess, pgrf refuses it). Rejected 19 rendered/vector ones (Altai,
#       Autumn, Canopee, Cascade, Cluster, Elarun, Flow, FlyingKonqui,
#       Honeywave, IceCold, Kay, Kokkini, MilkyWay, Opal, PastelHills, Patak,
#       SafeLanding, Shell, Volna) and every contents/screenshot.*.
#   lomiri-wallpapers-16.04 20.04.0-2    keep 14 photos (CC-BY-4.0,
#       CC-BY-SA-4.0, CC0-1.0). Rejected umang_by_Abhishek_Mudgal.jpg (abstract).
#   lomiri-wallpapers-20.04 20.04.0-2    keep Kleiber_by_Lukas_Baubkus.jpg.
#       Rejected Fossa, Infinite-Sea (rendered) and Painting-Colors (rendered,
#       and debian/copyright has no stanza for it).
#   lxqt-themes 1.2.0-1                  keep 11 photos in usr/share/lxqt/wallpapers
#       (debian/copyright LGPL-2.1+, upstream wallpapers/License CC-BY-SA-3.0).
#       Rejected the origami/plasma/triangles/waves/kde-plasma/simple_blue
#       ones (rendered, most with logos).
#   No photographs at all (not downloaded): gnome-backgrounds 43.1-1 (all
#   rendered 3D/vector; its copyright file still names photos that 43 no
#   longer ships), desktop-base 12.0.6+nmu1~deb12u1 (SVG/rendered themes,
#   logos), lomiri-wallpapers (warty-final-ubuntu.png, rendered),
#   ukui-wallpapers, sway-backgrounds, xfdesktop4-data, lxde-common,
#   cinnamon-desktop-data (no images), debian-edu-artwork-emerald (all
#   rendered), mypaint-data-extras (512x512 palette-quantised paper/canvas
#   texture tiles). Not examined: enlightenment-data (400 MB; its
#   backgrounds are .edj archives, not plain image files).
set -euo pipefail

prog=fetch_photos
die() { printf '%s: error: %s\n' "$prog" "$*" >&2; exit 1; }
warn() { printf '%s: %s\n' "$prog" "$*" >&2; }

ALLOW_DRIFT=0
DEST=
while (($#)); do
    case $1 in
        --allow-drift) ALLOW_DRIFT=1 ;;
        -h|--help) sed -n '2,/^# Examined/{/^# Examined/d;s/^# \{0,1\}//;p}' "$0"; exit 0 ;;
        -*) die "unknown option '$1' (usage: tools/fetch_photos.sh [--allow-drift] [DEST])" ;;
        *) [[ -z $DEST ]] || die "only one DEST folder may be given"; DEST=$1 ;;
    esac
    shift
done
DEST=${DEST:-${HOME:?HOME is not set}/.cache/pgrf/photos}

# package <space> path inside the package. Keep in step with tools/photos.tsv.
ALLOW=(
    "mate-backgrounds usr/share/backgrounds/mate/nature/Aqua.jpg"
    "mate-backgrounds usr/share/backgrounds/mate/nature/Blinds.jpg"
    "mate-backgrounds usr/share/backgrounds/mate/nature/Dune.jpg"
    "mate-backgrounds usr/share/backgrounds/mate/nature/FreshFlower.jpg"
    "mate-backgrounds usr/share/backgrounds/mate/nature/Garden.jpg"
    "mate-backgrounds usr/share/backgrounds/mate/nature/GreenMeadow.jpg"
    "mate-backgrounds usr/share/backgrounds/mate/nature/LadyBird.jpg"
    "mate-backgrounds usr/share/backgrounds/mate/nature/RainDrops.jpg"
    "mate-backgrounds usr/share/backgrounds/mate/nature/Storm.jpg"
    "mate-backgrounds usr/share/backgrounds/mate/nature/TwoWings.jpg"
    "mate-backgrounds usr/share/backgrounds/mate/nature/Wood.jpg"
    "mate-backgrounds usr/share/backgrounds/mate/nature/YellowFlower.jpg"
    "plasma-workspace-wallpapers usr/share/wallpapers/BytheWater/contents/images/2560x1600.jpg"
    "plasma-workspace-wallpapers usr/share/wallpapers/ColdRipple/contents/images/2560x1600.jpg"
    "plasma-workspace-wallpapers usr/share/wallpapers/ColorfulCups/contents/images/2560x1600.jpg"
    "plasma-workspace-wallpapers usr/share/wallpapers/DarkestHour/contents/images/2560x1600.jpg"
    "plasma-workspace-wallpapers usr/share/wallpapers/EveningGlow/contents/images/2560x1600.jpg"
    "plasma-workspace-wallpapers usr/share/wallpapers/FallenLeaf/contents/images/2560x1600.jpg"
    "plasma-workspace-wallpapers usr/share/wallpapers/Kite/contents/images/2560x1600.jpg"
    "plasma-workspace-wallpapers usr/share/wallpapers/OneStandsOut/contents/images/2560x1600.jpg"
    "plasma-workspace-wallpapers usr/share/wallpapers/Path/contents/images/2560x1600.jpg"
    "plasma-workspace-wallpapers usr/share/wallpapers/summer_1am/contents/images/2560x1600.jpg"
    "lomiri-wallpapers-16.04 usr/share/backgrounds/Bridge_by_Sander_Klootwijk.jpg"
    "lomiri-wallpapers-16.04 usr/share/backgrounds/Dragonfly_by_Bolly.jpg"
    "lomiri-wallpapers-16.04 usr/share/backgrounds/Picture_0B_by_freespace.jpg"
    "lomiri-wallpapers-16.04 usr/share/backgrounds/Picture_1A_by_freespace.jpg"
    "lomiri-wallpapers-16.04 usr/share/backgrounds/Wine_by_Jakkub_Mede.jpg"
    "lomiri-wallpapers-16.04 usr/share/backgrounds/aitzgorri_by_Aitzol_Berasategi.jpg"
    "lomiri-wallpapers-16.04 usr/share/backgrounds/analogpattern_by_Peter_Nerlich.jpg"
    "lomiri-wallpapers-16.04 usr/share/backgrounds/free_by_Peter_Nerlich.jpg"
    "lomiri-wallpapers-16.04 usr/share/backgrounds/friends_by_Aitzol_Berasategi.jpg"
    "lomiri-wallpapers-16.04 usr/share/backgrounds/greentock_by_Peter_Nerlich.jpg"
    "lomiri-wallpapers-16.04 usr/share/backgrounds/life_by_Aitzol_Berasategi.jpg"
    "lomiri-wallpapers-16.04 usr/share/backgrounds/picosdeeuropa_by_Aitzol_Berasategi.jpg"
    "lomiri-wallpapers-16.04 usr/share/backgrounds/seeding_by_Clements_Engelhardt.jpg"
    "lomiri-wallpapers-16.04 usr/share/backgrounds/sunset_by_Aitzol_Berasategi.jpg"
    "lomiri-wallpapers-20.04 usr/share/backgrounds/Kleiber_by_Lukas_Baubkus.jpg"
    "lxqt-themes usr/share/lxqt/wallpapers/Butterfly-Kenneth-Wimer.jpg"
    "lxqt-themes usr/share/lxqt/wallpapers/Valendas.png"
    "lxqt-themes usr/share/lxqt/wallpapers/after-the-rain.jpg"
    "lxqt-themes usr/share/lxqt/wallpapers/appleflower.png"
    "lxqt-themes usr/share/lxqt/wallpapers/beam.png"
    "lxqt-themes usr/share/lxqt/wallpapers/butterfly.png"
    "lxqt-themes usr/share/lxqt/wallpapers/cloud.png"
    "lxqt-themes usr/share/lxqt/wallpapers/drop.png"
    "lxqt-themes usr/share/lxqt/wallpapers/flowers.png"
    "lxqt-themes usr/share/lxqt/wallpapers/fog.jpg"
    "lxqt-themes usr/share/lxqt/wallpapers/this-is-not-windows.jpg"
)

# Name in DEST: <package>__<basename>; KDE wallpapers all end in <WxH>.<ext>,
# so theirs is <package>__<wallpaper name>.<ext>.
out_name() {
    local pkg=$1 path=$2 base=${2##*/}
    if [[ $path =~ /wallpapers/([^/]+)/contents/images/[^/]+$ ]]; then
        base=${BASH_REMATCH[1]}.${path##*.}
    fi
    printf '%s__%s' "$pkg" "$base"
}

command -v apt-get >/dev/null 2>&1 \
    || die "apt-get not found: this script needs a Debian or Ubuntu system (it fetches Debian packages)"
for tool in dpkg-deb sha256sum awk realpath; do
    command -v "$tool" >/dev/null 2>&1 || die "$tool not found (needed to unpack and verify the packages)"
done

here=$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd -P)
TSV=$here/photos.tsv
[[ -r $TSV ]] || die "$TSV not found (it lists the expected SHA-256 of every photo)"

# Read photos.tsv: package version path file author licence width height bytes sha256 notes
declare -A T_VER T_FILE T_SHA T_PIX
header=$(head -n1 "$TSV")
[[ $header == $'package\tversion\tpath\tfile\tauthor\tlicence\twidth\theight\tbytes\tsha256\tnotes' ]] \
    || die "unexpected header in $TSV"
while IFS=$'\t' read -r pkg ver path file _author _lic w h _bytes sha _notes; do
    key="$pkg $path"
    [[ -z ${T_SHA[$key]+x} ]] || die "duplicate row in photos.tsv: $key"
    T_VER[$key]=$ver T_FILE[$key]=$file T_SHA[$key]=$sha T_PIX[$key]=$((w * h))
done < <(tail -n +2 "$TSV")

declare -A IN_ALLOW
for entry in "${ALLOW[@]}"; do
    pkg=${entry%% *} path=${entry#* }
    [[ -n ${T_SHA[$entry]+x} ]] || die "allow-list entry has no row in photos.tsv: $entry"
    [[ ${T_FILE[$entry]} == "$(out_name "$pkg" "$path")" ]] \
        || die "photos.tsv file name for $entry is not $(out_name "$pkg" "$path")"
    IN_ALLOW[$entry]=1
done
for key in "${!T_SHA[@]}"; do
    [[ -n ${IN_ALLOW[$key]+x} ]] || die "photos.tsv row is not in the allow-list: $key"
done

dest_real=$(realpath -m -- "$DEST")
repo_root=$(cd "$here/.." && pwd -P)
if [[ $dest_real == "$repo_root" || $dest_real == "$repo_root"/* ]]; then
    die "refusing to put photos inside the repository ($dest_real): photos are never committed"
fi
mkdir -p -- "$dest_real" || die "cannot create $dest_real"

# Which packages are needed: those with a kept file missing or wrong in DEST.
sha_of() { sha256sum "$1" | awk '{print $1}'; }
declare -A NEED
PKGS=()
for entry in "${ALLOW[@]}"; do
    pkg=${entry%% *}
    dst=$dest_real/${T_FILE[$entry]}
    if [[ -f $dst && $(sha_of "$dst") == "${T_SHA[$entry]}" ]]; then continue; fi
    if [[ -z ${NEED[$pkg]+x} ]]; then NEED[$pkg]=1; PKGS+=("$pkg"); fi
done

tmp=$(mktemp -d "${TMPDIR:-/tmp}/fetch_photos.XXXXXX")
trap 'rm -rf "$tmp"' EXIT

drift=0
for pkg in "${PKGS[@]}"; do
    want=
    for entry in "${ALLOW[@]}"; do
        [[ ${entry%% *} == "$pkg" ]] && { want=${T_VER[$entry]}; break; }
    done
    work=$tmp/$pkg
    mkdir -p "$work"
    chmod 755 "$tmp" "$work"   # lets apt's unprivileged _apt user write there
    # The version photos.tsv was made from, else whatever apt offers now.
    if ! (cd "$work" && apt-get download "$pkg=$want") >"$work/apt.log" 2>&1; then
        if ! (cd "$work" && apt-get download "$pkg") >"$work/apt.log" 2>&1; then
            reason=$(grep -m1 '^E:' "$work/apt.log" || tail -n1 "$work/apt.log" || true)
            die "cannot download package $pkg (${reason:-apt-get download failed}); run 'apt-get update' first if the package lists are missing or old"
        fi
    fi
    debs=("$work"/*.deb)
    [[ ${#debs[@]} -eq 1 && -f ${debs[0]} ]] || die "apt-get download $pkg left no single .deb file"
    got=$(dpkg-deb -f "${debs[0]}" Version)
    if [[ $got != "$want" ]]; then
        warn "drift: $pkg $want is no longer available; got $got, checking its files against photos.tsv"
    fi
    dpkg-deb -x "${debs[0]}" "$work/root"
    for entry in "${ALLOW[@]}"; do
        [[ ${entry%% *} == "$pkg" ]] || continue
        path=${entry#* }
        src=$work/root/$path
        dst=$dest_real/${T_FILE[$entry]}
        if [[ ! -f $src ]]; then
            warn "drift: $pkg $got has no $path"
            drift=$((drift + 1))
            continue
        fi
        sum=$(sha_of "$src")
        if [[ $sum != "${T_SHA[$entry]}" ]]; then
            warn "drift: $pkg $got: $path has SHA-256 $sum, photos.tsv ($want) has ${T_SHA[$entry]}"
            drift=$((drift + 1))
            ((ALLOW_DRIFT)) || continue
            warn "copying it anyway (--allow-drift); its size in photos.tsv may be wrong"
        fi
        cp "$src" "$dst.part"
        chmod 0644 "$dst.part"
        mv -f "$dst.part" "$dst"
    done
    rm -rf "$work"
done

if ((drift)) && ! ((ALLOW_DRIFT)); then
    die "$drift file(s) differ from tools/photos.tsv (listed above: the package changed): look at them, update photos.tsv, or rerun with --allow-drift"
fi

n=0 pix=0
for entry in "${ALLOW[@]}"; do
    [[ -f $dest_real/${T_FILE[$entry]} ]] || continue
    n=$((n + 1)) pix=$((pix + T_PIX[$entry]))
done
awk -v n="$n" -v p="$pix" -v d="$dest_real" -v prog="$prog" \
    'BEGIN { printf "%s: %d photographs, %.1f megapixels, in %s\n", prog, n, p / 1e6, d }'
