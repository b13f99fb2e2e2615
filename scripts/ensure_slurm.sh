#!/usr/bin/env bash
# Installs Debian's Slurm (slurmctld, slurmd, client commands) and MUNGE when they are missing, for
# the tests that run a private one-node cluster (tests/slurm). Idempotent: with the commands
# present it does nothing. The packages' own services are NOT started (a policy-rc.d forbids it
# during the install): the tests start their own daemons with a private configuration.
# Needs root (or sudo) and apt-get; elsewhere it says what to install and exits 1.
set -euo pipefail
need=()
for cmd in slurmctld slurmd sbatch scontrol munged; do
  command -v "$cmd" >/dev/null 2>&1 || [ -x "/usr/sbin/$cmd" ] || need+=("$cmd")
done
[ ${#need[@]} -eq 0 ] && exit 0
if ! command -v apt-get >/dev/null 2>&1; then
  echo "ensure_slurm: missing ${need[*]}; install Slurm (slurmctld, slurmd, client) and MUNGE" >&2
  exit 1
fi
sudo=()
if [ "$(id -u)" != 0 ]; then
  command -v sudo >/dev/null 2>&1 || { echo "ensure_slurm: missing ${need[*]}; run as root to install slurm-wlm and munge" >&2; exit 1; }
  sudo=(sudo)
fi
echo "ensure_slurm: installing slurm-wlm and munge (missing: ${need[*]})" >&2
# no service starts inside install scripts: the tests run their own daemons
policy=/usr/sbin/policy-rc.d
own_policy=0
if [ ! -e "$policy" ]; then
  printf '#!/bin/sh\nexit 101\n' | "${sudo[@]}" tee "$policy" >/dev/null
  "${sudo[@]}" chmod 755 "$policy"
  own_policy=1
fi
trap '[ "$own_policy" = 1 ] && "${sudo[@]}" rm -f "$policy"' EXIT
export DEBIAN_FRONTEND=noninteractive
# the package lists may be missing or stale on a fresh machine
"${sudo[@]}" apt-get install -y -q --no-install-recommends slurmctld slurmd slurm-client munge >/dev/null 2>&1 || {
  "${sudo[@]}" apt-get update -q >/dev/null
  "${sudo[@]}" apt-get install -y -q --no-install-recommends slurmctld slurmd slurm-client munge >/dev/null
}
