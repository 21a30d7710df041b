#!/bin/sh
# Runs a test binary inside a private user + network namespace prepared for Aravis's fake GigE
# Vision cameras (arv-fake-gv-camera-0.8):
# - the loopback interface is up and also holds 127.0.0.2, so that two fake cameras can each
#   have an address of their own (127.0.0.1 and 127.0.0.2);
# - the GVCP port 3956 and the discovery broadcasts are private, so that tests running in
#   parallel (or real cameras on the host's network) cannot interfere.
# No root needed: an unprivileged user namespace maps the caller to root inside it.
#
# Usage: fake_camera_netns.sh TEST_BINARY [ARGS...]
# Fails (exit 1, with the reason) when the namespace cannot be created: the test must not pass
# or skip silently where it cannot run.
set -eu

if [ "$#" -lt 1 ]; then
  echo "usage: $0 TEST_BINARY [ARGS...]" >&2
  exit 2
fi

if [ "${STEVI_FAKE_CAMERA_NETNS:-}" != "inside" ]; then
  for tool in unshare ip; do
    if ! command -v "$tool" >/dev/null 2>&1; then
      echo "fake_camera_netns.sh: '$tool' not found (install util-linux and iproute2)" >&2
      exit 1
    fi
  done
  # Probe first, so that a refusal is reported as such and not as a test failure.
  if ! probe_error=$(unshare --user --map-root-user --net true 2>&1); then
    # No namespace (a container without user namespaces, say). As root, the host's loopback can
    # take 127.0.0.2 instead; the tests that use fake cameras hold a ctest RESOURCE_LOCK, so they
    # never run at the same time on the shared port.
    if ip -4 addr show dev lo | grep -q ' 127\.0\.0\.2/' ||
       ip addr add 127.0.0.2/8 dev lo 2>/dev/null; then
      echo "fake_camera_netns.sh: no private namespace ($probe_error); using the host's loopback" \
           "with 127.0.0.2" >&2
      export STEVI_FAKE_CAMERA_NETNS=inside
      exec "$@"
    fi
    echo "fake_camera_netns.sh: cannot create a user + network namespace: $probe_error" >&2
    echo "  (unprivileged user namespaces may be disabled: see sysctl" \
         "kernel.unprivileged_userns_clone, user.max_user_namespaces and, on Ubuntu," \
         "kernel.apparmor_restrict_unprivileged_userns; containers may need" \
         "--security-opt seccomp=unconfined or CAP_SYS_ADMIN; as root the host's loopback" \
         "would do, but 127.0.0.2 could not be added to it either)" >&2
    exit 1
  fi
  export STEVI_FAKE_CAMERA_NETNS=inside
  exec unshare --user --map-root-user --net /bin/sh "$0" "$@"
fi

# Inside the namespace.
if ! ip link set lo up || ! ip addr add 127.0.0.2/8 dev lo; then
  echo "fake_camera_netns.sh: cannot configure the loopback interface in the namespace" >&2
  exit 1
fi
exec "$@"
