#!/usr/bin/env bash
# Renders one frame across a Slurm job array: N array tasks each render one
# part (vox-render --tiles I/N), then a dependent job merges them (vox-merge).
#
#   scripts/slurm/submit.sh [--wait] [--preview out.png] STORE CAM.json OUT.exr N [vox-render flags...]
#
# Parts and logs go to OUT.parts/. With --wait, blocks until the merge has
# finished and exits non-zero if any part or the merge failed. Binaries come
# from $VOX_RENDER and $VOX_MERGE (default: vox-render, vox-merge on PATH);
# give absolute paths, the jobs may run in another directory.
set -euo pipefail
here=$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)
wait_flag=()
merge_flags=()
while [[ $# -gt 0 ]]; do
  case $1 in
    --wait) wait_flag=(--wait); shift ;;
    --preview) merge_flags+=(--preview "$(realpath -m "$2")"); shift 2 ;;
    *) break ;;
  esac
done
if [[ $# -lt 4 ]]; then
  sed -n '2,12p' "$0" >&2
  exit 2
fi
store=$(realpath "$1") cam=$(realpath "$2") out=$(realpath -m "$3") n=$4
shift 4
[[ $n =~ ^[1-9][0-9]*$ ]] || { echo "submit.sh: N must be a positive integer, not '$n'" >&2; exit 2; }
work="${out%.exr}.parts"
mkdir -p "$work"
export VOX_RENDER=${VOX_RENDER:-$(command -v vox-render || echo vox-render)}
export VOX_MERGE=${VOX_MERGE:-$(command -v vox-merge || echo vox-merge)}
array_job=$(sbatch --parsable --export=ALL --array="1-$n" --chdir="$work" \
  --output="$work/part-%a.log" "$here/render-part.sbatch" "$store" "$cam" "$work" "$@")
array_job=${array_job%%;*}
echo "submitted render array $array_job ($n parts)"
set +e
merge_job=$(sbatch --parsable --export=ALL --dependency="afterok:$array_job" --kill-on-invalid-dep=yes \
  --chdir="$work" --output="$work/merge.log" "${wait_flag[@]}" \
  "$here/merge.sbatch" "$work" "$n" "$out" "${merge_flags[@]}")
status=$?
set -e
echo "submitted merge ${merge_job%%;*} -> $out"
if [[ ${#wait_flag[@]} -gt 0 ]]; then
  if [[ $status -ne 0 || ! -f $out ]]; then
    echo "submit.sh: the split render failed; logs in $work" >&2
    exit 1
  fi
  echo "done: $out"
fi
exit $status
