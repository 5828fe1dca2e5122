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
#
# Or renders a frame sequence (a --cam array, --turntable N) across a job
# array, each task a chunk of K frames (default 1) in one vox-render process
# (render-frames.sbatch):
#
#   scripts/slurm/submit.sh --frames FRAMES [--chunk K] [--wait] STORE OUT.%04d.exr [vox-render flags...]
#
# FRAMES is the sequence's length (as --turntable or the --cam array says);
# the flags give the sequence and run in the current directory, so relative
# paths in them hold; logs go to OUT's directory, frames-I.log. With --wait,
# blocks until every task has finished and exits non-zero if one failed.
#
# Resources, before the other arguments, go to every sbatch call:
#   --partition P  --time T  --mem M  --cpus-per-task N  --sbatch-arg ARG (repeatable)
# A missing sbatch, or a submission sbatch refuses, exits 1 with its message.
set -euo pipefail
here=$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)
wait_flag=()
merge_flags=()
res=()  # resources for sbatch
frames='' chunk=1
while [[ $# -gt 0 ]]; do
  case $1 in
    --wait) wait_flag=(--wait); shift ;;
    --preview) merge_flags+=(--preview "$(realpath -m "$2")"); shift 2 ;;
    --frames) frames=$2; shift 2 ;;
    --chunk) chunk=$2; shift 2 ;;
    --partition|--time|--mem|--cpus-per-task) res+=("$1=$2"); shift 2 ;;
    --sbatch-arg) res+=("$2"); shift 2 ;;
    *) break ;;
  esac
done
command -v sbatch >/dev/null || { echo "submit.sh: sbatch not found: run this on a Slurm login node" >&2; exit 1; }
# sbatch with the resources; on failure, says which submission failed and exits 1.
submit() {
  local what=$1 out
  shift
  if ! out=$(sbatch "${res[@]}" "$@"); then
    echo "submit.sh: sbatch refused the $what" >&2
    exit 1
  fi
  printf '%s' "$out"
}
if [[ -n $frames ]]; then
  # A frame sequence: an array of ceil(FRAMES / K) tasks.
  if [[ $# -lt 2 ]]; then
    sed -n '2,27p' "$0" >&2
    exit 2
  fi
  [[ $frames =~ ^[1-9][0-9]*$ ]] || { echo "submit.sh: --frames must be a positive integer, not '$frames'" >&2; exit 2; }
  [[ $chunk =~ ^[1-9][0-9]*$ ]] || { echo "submit.sh: --chunk must be a positive integer, not '$chunk'" >&2; exit 2; }
  [[ ${#merge_flags[@]} -eq 0 ]] || { echo "submit.sh: with --frames, give --preview P.%04d.png after OUT (a vox-render flag)" >&2; exit 2; }
  store=$(realpath "$1") out=$(realpath -m "$2")
  shift 2
  logs=$(dirname "$out")
  mkdir -p "$logs"
  export VOX_RENDER=${VOX_RENDER:-$(command -v vox-render || echo vox-render)}
  tasks=$(( (frames + chunk - 1) / chunk ))
  set +e
  job=$(sbatch "${res[@]}" --parsable --export=ALL --array="1-$tasks" --chdir="$PWD" \
    --output="$logs/frames-%a.log" "${wait_flag[@]}" \
    "$here/render-frames.sbatch" "$store" "$frames" "$chunk" "$out" "$@")
  status=$?
  set -e
  if [[ -z $job ]]; then
    echo "submit.sh: sbatch refused the frames array" >&2
    exit 1
  fi
  echo "submitted frames array ${job%%;*} ($frames frames in $tasks tasks of up to $chunk) -> $out"
  if [[ ${#wait_flag[@]} -gt 0 ]]; then
    if [[ $status -ne 0 ]]; then
      echo "submit.sh: a frames task failed; logs in $logs/frames-*.log" >&2
      exit 1
    fi
    echo "done: $out"
  fi
  exit $status
fi
if [[ $# -lt 4 ]]; then
  sed -n '2,27p' "$0" >&2
  exit 2
fi
store=$(realpath "$1") cam=$(realpath "$2") out=$(realpath -m "$3") n=$4
shift 4
[[ $n =~ ^[1-9][0-9]*$ ]] || { echo "submit.sh: N must be a positive integer, not '$n'" >&2; exit 2; }
work="${out%.exr}.parts"
mkdir -p "$work"
export VOX_RENDER=${VOX_RENDER:-$(command -v vox-render || echo vox-render)}
export VOX_MERGE=${VOX_MERGE:-$(command -v vox-merge || echo vox-merge)}
array_job=$(submit "render array" --parsable --export=ALL --array="1-$n" --chdir="$work" \
  --output="$work/part-%a.log" "$here/render-part.sbatch" "$store" "$cam" "$work" "$@")
array_job=${array_job%%;*}
echo "submitted render array $array_job ($n parts)"
set +e
merge_job=$(sbatch "${res[@]}" --parsable --export=ALL --dependency="afterok:$array_job" --kill-on-invalid-dep=yes \
  --chdir="$work" --output="$work/merge.log" "${wait_flag[@]}" \
  "$here/merge.sbatch" "$work" "$n" "$out" "${merge_flags[@]}")
status=$?
set -e
if [[ -z $merge_job ]]; then
  echo "submit.sh: sbatch refused the merge" >&2
  exit 1
fi
echo "submitted merge ${merge_job%%;*} -> $out"
if [[ ${#wait_flag[@]} -gt 0 ]]; then
  if [[ $status -ne 0 || ! -f $out ]]; then
    echo "submit.sh: the split render failed; logs in $work" >&2
    exit 1
  fi
  echo "done: $out"
fi
exit $status
