#!/usr/bin/env bash
# A throwaway PKI for running crossroads with TLS and a token: a self-signed
# CA, one server certificate for the replay and the learner, one client
# certificate (for mutual TLS) and a random token, as PEM files in OUT
# (default deploy/certs, which git ignores).
#
#   deploy/make-certs.sh [OUT]
#   docker compose -f deploy/compose.yaml -f deploy/compose.tls.yaml up -d
#
# The server certificate names every way the roles are reached: the compose
# services (replay, learner), the Kubernetes Services (crossroads-replay,
# crossroads-learner, with their namespace's names under EXTRA_SANS),
# localhost and 127.0.0.1. Add names with EXTRA_SANS="DNS:a.example,IP:10.0.0.5".
# DAYS sets the validity (default 365). An existing OUT is not overwritten
# unless FORCE=1.
#
# The files are world-readable so that the containers' user (uid 10001)
# can read them through a bind mount: this is a local CA for one machine.
# Anywhere else keep keys in a secret store (a Kubernetes Secret, see
# deploy/k8s-tls/).
set -euo pipefail

here=$(cd "$(dirname "$0")" && pwd)
out=${1:-$here/certs}
days=${DAYS:-365}
sans="DNS:replay,DNS:learner,DNS:crossroads-replay,DNS:crossroads-learner,DNS:localhost,IP:127.0.0.1"
if [[ -n "${EXTRA_SANS:-}" ]]; then
    sans="$sans,$EXTRA_SANS"
fi

if [[ -e "$out/ca.pem" && "${FORCE:-0}" != 1 ]]; then
    echo "error: $out already holds certificates; FORCE=1 replaces them" >&2
    exit 1
fi
command -v openssl >/dev/null || { echo "error: openssl is not installed" >&2; exit 1; }
mkdir -p "$out"
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT

key() { openssl genpkey -algorithm EC -pkeyopt ec_paramgen_curve:P-256 -out "$1" 2>/dev/null; }

# The CA.
key "$tmp/ca.key"
openssl req -x509 -new -key "$tmp/ca.key" -sha256 -days "$days" \
    -subj "/CN=crossroads local CA" \
    -addext "basicConstraints=critical,CA:TRUE" \
    -addext "keyUsage=critical,keyCertSign,cRLSign" \
    -out "$tmp/ca.pem"

# A leaf signed by the CA: sign NAME CN USAGE [SANS].
sign() {
    local name=$1 cn=$2 usage=$3 san=${4:-}
    key "$tmp/$name.key"
    openssl req -new -key "$tmp/$name.key" -subj "/CN=$cn" -out "$tmp/$name.csr"
    {
        echo "basicConstraints=critical,CA:FALSE"
        echo "keyUsage=critical,digitalSignature"
        echo "extendedKeyUsage=$usage"
        if [[ -n "$san" ]]; then echo "subjectAltName=$san"; fi
    } >"$tmp/$name.ext"
    openssl x509 -req -in "$tmp/$name.csr" -CA "$tmp/ca.pem" -CAkey "$tmp/ca.key" \
        -CAcreateserial -sha256 -days "$days" -extfile "$tmp/$name.ext" \
        -out "$tmp/$name.pem" 2>/dev/null
    openssl verify -CAfile "$tmp/ca.pem" "$tmp/$name.pem" >/dev/null
}
sign server "crossroads server" serverAuth "$sans"
sign client "crossroads client" clientAuth

# 32 random bytes as hex: printable, no padding or newline issues.
openssl rand -hex 32 >"$tmp/token"

for f in ca.pem ca.key server.pem server.key client.pem client.key token; do
    install -m 0644 "$tmp/$f" "$out/$f"
done
# The CA's key signs nothing after this; keep it only for the owner.
chmod 0600 "$out/ca.key"
echo "wrote $out: ca.pem, server.pem/.key, client.pem/.key, token (CA key: ca.key)"
echo "Kubernetes: kubectl create secret generic crossroads-tls \\"
for f in ca.pem server.pem server.key client.pem client.key token; do
    echo "    --from-file=$f=$out/$f \\"
done
echo "    --dry-run=client -o yaml | kubectl apply -f -"
