#!/usr/bin/env bash
# scripts/slurm/submit.sh against a stand-in sbatch that records its
# arguments: resources reach every submission; a missing sbatch and a
# refused submission exit 1 with a message, never "submitted".
set -uo pipefail
submit=$(cd "$(dirname "$0")/../../scripts/slurm" && pwd)/submit.sh
dir=$(mktemp -d)
trap 'rm -rf "$dir"' EXIT
fail() { echo "FAIL: $*" >&2; exit 1; }
mkdir "$dir/bin" "$dir/store"
touch "$dir/cam.json"
cat > "$dir/bin/sbatch" <<'SB'
#!/usr/bin/env bash
echo "$*" >> "$SBATCH_LOG"
[[ -n ${SBATCH_FAIL:-} ]] && { echo "sbatch: error: invalid partition" >&2; exit 1; }
echo 42
SB
chmod +x "$dir/bin/sbatch"
export SBATCH_LOG=$dir/log
PATH="$dir/bin:$PATH" "$submit" --partition gpu --time 1:00:00 --mem 8G --cpus-per-task 16 \
  --sbatch-arg --account=lab "$dir/store" "$dir/cam.json" "$dir/out.exr" 4 > "$dir/stdout" 2>&1 || fail "submit: $(cat "$dir/stdout")"
[[ $(wc -l < "$dir/log") -eq 2 ]] || fail "two submissions expected: $(cat "$dir/log")"
while read -r line; do
  for want in --partition=gpu --time=1:00:00 --mem=8G --cpus-per-task=16 --account=lab; do
    [[ " $line " == *" $want "* ]] || fail "'$want' missing from: $line"
  done
done < "$dir/log"
: > "$dir/log"
PATH="$dir/bin:$PATH" "$submit" --frames 3 --mem 2G "$dir/store" "$dir/f.%04d.exr" > "$dir/stdout" 2>&1 || fail "frames: $(cat "$dir/stdout")"
grep -q -- "--mem=2G" "$dir/log" || fail "frames: --mem missing: $(cat "$dir/log")"
# sbatch refuses: exit 1, no "submitted".
out=$(SBATCH_FAIL=1 PATH="$dir/bin:$PATH" "$submit" "$dir/store" "$dir/cam.json" "$dir/out.exr" 4 2>&1); code=$?
[[ $code -eq 1 && $out == *"sbatch refused the render array"* && $out != *submitted* ]] || fail "refused: $code $out"
out=$(SBATCH_FAIL=1 PATH="$dir/bin:$PATH" "$submit" --frames 3 "$dir/store" "$dir/f.%04d.exr" 2>&1); code=$?
[[ $code -eq 1 && $out == *"sbatch refused the frames array"* && $out != *submitted* ]] || fail "frames refused: $code $out"
# No sbatch at all (a PATH of what the script runs before it looks for
# sbatch: the machine's own PATH may hold a real one).
mkdir "$dir/nosbatch"
for tool in bash dirname; do ln -s "$(command -v "$tool")" "$dir/nosbatch/$tool"; done
out=$(PATH=$dir/nosbatch "$submit" --frames 3 "$dir/store" "$dir/f.%04d.exr" 2>&1); code=$?
[[ $code -eq 1 && $out == *"sbatch not found"* ]] || fail "missing sbatch: $code $out"
echo "slurm_submit_test: ok"
