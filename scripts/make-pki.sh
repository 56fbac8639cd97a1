#!/usr/bin/env bash
# Makes a DDS Security PKI for densemap (openssl only) in DIR:
#   ca.pem, ca.key            one CA: it signs every identity and the two documents
#   {server,robot,operator,viewer}.pem/.key   an identity per role (EC P-256)
#   governance.xml/.p7s       every densemap and ROS topic: authenticated, access-controlled,
#                             discovery and data encrypted (AES-GCM); no unauthenticated joins
#   permissions.xml/.p7s      one grant per role, default DENY:
#     server    publishes and subscribes every topic
#     robot     publishes scans (densemap/scan, ROS clouds and /tf) and pose corrections
#               (densemap/pose_correction), reads status and map
#               events (which scans the map holds)
#     operator  commands (reset, clear-bbox, save), queries, map fetches, map topics, status
#     viewer    queries, map fetches, map topics and status only
# Certificates and grants are valid from now for DAYS days (default 365; --days N).
# The server's config then names DIR/ca.pem, DIR/server.pem, DIR/server.key, DIR/ca.pem,
# DIR/governance.p7s, DIR/permissions.p7s; a client uses `densemap --pki DIR --role R`.
#
# Usage: scripts/make-pki.sh [--days N] [--domains MIN-MAX] DIR
# The private keys are unencrypted (0600): keep DIR on the robot, and give each machine only
# the files of its role.
set -euo pipefail

usage() {
  cat <<'USAGE'
Usage: densemap-make-pki [--days N] [--domains MIN-MAX] DIR
Makes a DDS Security PKI for densemap-server and its clients in DIR (openssl only): a CA,
an identity per role (server, robot, operator, viewer), and the signed governance and
permissions documents (one grant per role, default deny).

Options:
  --days N            certificates and grants valid for N days from now (default 365)
  --domains MIN-MAX   DDS domain ids the documents cover (default 0-230)
  -h, --help          print this help and exit
  --version           print the version and exit

The server's config then names DIR/ca.pem, DIR/server.pem, DIR/server.key,
DIR/governance.p7s and DIR/permissions.p7s; a client uses `densemap --pki DIR --role R`.
The private keys are unencrypted (0600): give each machine only the files of its role.
USAGE
}
case "${1:-}" in
  -h | --help) usage; exit 0 ;;
  --version)
    version="@DENSEMAP_VERSION@"  # set where the package installs it (DensemapInstall.cmake)
    [[ $version == "@"* ]] && version="source tree"
    echo "densemap-make-pki (densemap) $version"
    exit 0
    ;;
esac

days=365
domains="0-230"
while [[ $# -gt 1 ]]; do
  case "$1" in
    --days) days="$2"; shift 2 ;;
    --domains) domains="$2"; shift 2 ;;
    *) echo "make-pki: unknown option $1" >&2; exit 2 ;;
  esac
done
if [[ $# -ne 1 ]]; then
  echo "usage: $0 [--days N] [--domains MIN-MAX] DIR" >&2
  exit 2
fi
dir="$1"
if ! [[ "$days" =~ ^[0-9]+$ ]] || (( days < 1 || days > 3650 )); then
  echo "make-pki: --days must be 1 .. 3650" >&2
  exit 2
fi
if ! [[ "$domains" =~ ^([0-9]+)-([0-9]+)$ ]] || (( BASH_REMATCH[2] > 230 ||
                                                   BASH_REMATCH[1] > BASH_REMATCH[2] )); then
  echo "make-pki: --domains must be MIN-MAX within 0-230" >&2
  exit 2
fi
domain_min="${BASH_REMATCH[1]}"
domain_max="${BASH_REMATCH[2]}"
command -v openssl >/dev/null || { echo "make-pki: openssl is not installed" >&2; exit 1; }
if [[ -e "$dir/ca.key" ]]; then
  echo "make-pki: $dir already holds a PKI (ca.key); remove it first" >&2
  exit 1
fi
mkdir -p "$dir"
umask 077
cd "$dir"

subject() { echo "/C=XX/O=densemap/CN=$1"; }
# The same subject as the permissions document writes it (RFC 4514 order, as Cyclone compares).
grant_subject() { echo "CN=$1,O=densemap,C=XX"; }

openssl req -x509 -newkey ec -pkeyopt ec_paramgen_curve:prime256v1 -nodes -sha256 \
  -keyout ca.key -out ca.pem -days "$days" -subj "$(subject "densemap CA")" 2>/dev/null
roles=(server robot operator viewer)
for role in "${roles[@]}"; do
  openssl req -new -newkey ec -pkeyopt ec_paramgen_curve:prime256v1 -nodes -sha256 \
    -keyout "$role.key" -out "$role.csr" -subj "$(subject "$role")" 2>/dev/null
  openssl x509 -req -in "$role.csr" -CA ca.pem -CAkey ca.key -CAcreateserial -sha256 \
    -days "$days" -out "$role.pem" 2>/dev/null
  rm -f "$role.csr"
done
rm -f ca.srl

not_before="$(date -u -d '-1 hour' +%Y-%m-%dT%H:%M:%S)"
not_after="$(date -u -d "+$days days" +%Y-%m-%dT%H:%M:%S)"
domain_xml="<domains><id_range><min>$domain_min</min><max>$domain_max</max></id_range></domains>"

cat > governance.xml <<EOF
<?xml version="1.0" encoding="UTF-8"?>
<dds xmlns:xsi="http://www.w3.org/2001/XMLSchema-instance"
     xsi:noNamespaceSchemaLocation="http://www.omg.org/spec/DDS-SECURITY/20170901/omg_shared_ca_governance.xsd">
  <domain_access_rules>
    <domain_rule>
      $domain_xml
      <allow_unauthenticated_participants>false</allow_unauthenticated_participants>
      <enable_join_access_control>true</enable_join_access_control>
      <discovery_protection_kind>ENCRYPT</discovery_protection_kind>
      <liveliness_protection_kind>ENCRYPT</liveliness_protection_kind>
      <rtps_protection_kind>NONE</rtps_protection_kind>
      <topic_access_rules>
        <topic_rule>
          <topic_expression>*</topic_expression>
          <enable_discovery_protection>true</enable_discovery_protection>
          <enable_liveliness_protection>true</enable_liveliness_protection>
          <enable_read_access_control>true</enable_read_access_control>
          <enable_write_access_control>true</enable_write_access_control>
          <metadata_protection_kind>ENCRYPT</metadata_protection_kind>
          <data_protection_kind>ENCRYPT</data_protection_kind>
        </topic_rule>
      </topic_access_rules>
    </domain_rule>
  </domain_access_rules>
</dds>
EOF

topics() {  # topics() NAME... -> <topics><topic>NAME</topic>...</topics>
  printf '<topics>'
  printf '<topic>%s</topic>' "$@"
  printf '</topics>'
}
queries_out=(densemap/query/point/request densemap/query/bbox/request densemap/query/ray/request
             densemap/query/distance/request densemap/query/path/request
             densemap/query/boxes/request densemap/query/distance_box/request densemap/map/request)
queries_in=(densemap/query/point/reply densemap/query/bbox/reply densemap/query/ray/reply
            densemap/query/distance/reply densemap/query/path/reply densemap/query/boxes/reply
            densemap/query/distance_box/reply densemap/cmd/reply)
map_in=(densemap/map/manifest densemap/map/tiles densemap/map/delta densemap/map/events
        densemap/status rt/octomap_binary rt/projected_map rt/octomap_point_cloud_centers)

# Every partition: replies travel in the asking client's own partition (densemap.reply.<id>),
# everything else in the default one.
partitions='<partitions><partition>*</partition></partitions>'
grant() {  # grant ROLE PUBLISH_TOPICS_XML SUBSCRIBE_TOPICS_XML
  cat <<EOF
    <grant name="densemap_$1">
      <subject_name>$(grant_subject "$1")</subject_name>
      <validity><not_before>$not_before</not_before><not_after>$not_after</not_after></validity>
      <allow_rule>
        $domain_xml
        <publish>$2$partitions</publish>
        <subscribe>$3$partitions</subscribe>
      </allow_rule>
      <default>DENY</default>
    </grant>
EOF
}
{
  cat <<EOF
<?xml version="1.0" encoding="UTF-8"?>
<dds xmlns:xsi="http://www.w3.org/2001/XMLSchema-instance"
     xsi:noNamespaceSchemaLocation="http://www.omg.org/spec/DDS-SECURITY/20170901/omg_shared_ca_permissions.xsd">
  <permissions>
EOF
  grant server "$(topics '*')" "$(topics '*')"
  grant robot "$(topics densemap/scan densemap/pose_correction rt/points 'rt/points*' rt/tf \
    rt/tf_static)" \
    "$(topics densemap/status densemap/map/events)"
  grant operator "$(topics densemap/cmd/request "${queries_out[@]}")" \
    "$(topics "${queries_in[@]}" "${map_in[@]}")"
  grant viewer "$(topics "${queries_out[@]}")" "$(topics "${queries_in[@]}" "${map_in[@]}")"
  cat <<EOF
  </permissions>
</dds>
EOF
} > permissions.xml

for doc in governance permissions; do
  openssl smime -sign -text -in "$doc.xml" -out "$doc.p7s" -signer ca.pem -inkey ca.key
done
chmod 0644 ./*.pem ./*.xml ./*.p7s
echo "make-pki: $(pwd): CA, identities ${roles[*]}, signed governance and permissions;" \
  "valid $not_before .. $not_after UTC, domains $domain_min-$domain_max"
