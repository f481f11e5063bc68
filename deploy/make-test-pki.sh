#!/bin/sh
# Makes a throwaway certificate authority and certificates for trying the service's TLS
# (docs/service/security.md); the tests and the secure load test make theirs with it at run
# time, so that no key is ever committed. Not for production: the keys are unencrypted and the
# certificates last 30 days.
#
#   deploy/make-test-pki.sh DIR [CLIENT ...]
#
# Writes into DIR: ca.pem, ca.key (the CA); server.pem, server.key (for localhost, 127.0.0.1 and
# ::1); client-NAME.pem, client-NAME.key for each CLIENT; other-ca.pem and other-client.pem/.key,
# a client certificate from an unrelated CA (for tests that must see it refused).
set -eu
if [ $# -lt 1 ]; then
  echo "usage: $0 DIR [CLIENT ...]" >&2
  exit 64
fi
dir=$1
shift
mkdir -p "$dir"
cd "$dir"
umask 077
key() { openssl genpkey -algorithm EC -pkeyopt ec_paramgen_curve:P-256 -out "$1" 2>/dev/null; }
# sign NAME CA SUBJECT EXTENSIONS
sign() {
  key "$1.key"
  openssl req -new -key "$1.key" -subj "$3" -out "$1.csr" 2>/dev/null
  printf '%s\n' "$4" > "$1.ext"
  openssl x509 -req -in "$1.csr" -CA "$2.pem" -CAkey "$2.key" -CAcreateserial -days 30 \
    -extfile "$1.ext" -out "$1.pem" 2>/dev/null
  rm -f "$1.csr" "$1.ext"
}
ca() {
  key "$1.key"
  openssl req -x509 -new -key "$1.key" -subj "$2" -days 30 -out "$1.pem" \
    -addext "basicConstraints=critical,CA:TRUE" -addext "keyUsage=critical,keyCertSign,cRLSign" \
    2>/dev/null
}
ca ca "/CN=radiosity test CA"
sign server ca "/CN=localhost" \
  "subjectAltName=DNS:localhost,IP:127.0.0.1,IP:::1
extendedKeyUsage=serverAuth"
for name in "$@"; do
  sign "client-$name" ca "/CN=$name" "extendedKeyUsage=clientAuth"
done
ca other-ca "/CN=unrelated CA"
sign other-client other-ca "/CN=intruder" "extendedKeyUsage=clientAuth"
rm -f ./*.srl
chmod 644 ./*.pem
