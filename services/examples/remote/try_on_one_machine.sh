#!/bin/sh
# Runs pendulum_remote.toml with its "companion" made on this machine: a network namespace
# joined to this one by a veth pair, with a /dev/shm of its own, so the two hosts meet only over
# the link, as two computers would. Needs root, ip (iproute2), nsenter, unshare and mount
# (util-linux). Run from the repository root after `cargo build --release`; any extra arguments
# go to `looplab run` (`--fault "cut bridge at 2s for 300ms"`, `--mode lockstep`).
set -eu
name=looplab-companion
mounts=/run/$name.mnt
looplab=${LOOPLAB:-target/release/looplab}

clean_up() {
    ip netns delete $name 2>/dev/null || true
    ip link delete llcompanion0 2>/dev/null || true
    umount $mounts 2>/dev/null || true
    rm -f $mounts
}
trap clean_up EXIT
clean_up

ip netns add $name
ip link add llcompanion0 type veth peer name llcompanion1 netns $name
ip address add 10.78.0.1/24 dev llcompanion0
ip link set llcompanion0 up
ip -n $name address add 10.78.0.2/24 dev llcompanion1
ip -n $name link set llcompanion1 up
ip -n $name link set lo up
# The companion's own /dev/shm, kept in a mount namespace bound to a file. Its copy of this
# machine's mounts would hold the network namespace alive: it lets go of /run/netns.
touch $mounts
unshare --mount=$mounts --propagation private sh -c \
    'mount -t tmpfs -o mode=1777 tmpfs /dev/shm && { umount -l /run/netns; true; } 2>/dev/null'

"$looplab" run services/examples/remote/pendulum_remote.toml \
    --set hosts.companion.address=10.78.0.2 \
    --set "hosts.companion.command=[\"nsenter\", \"--net=/run/netns/$name\", \"--mount=$mounts\", \"--wd=.\"]" \
    "$@"
