# What `cmake --install` and `cpack -G DEB` ship, in two components:
#   server: the programs, the default config in /etc/densemap, the systemd unit, the ILN model
#           (package densemap-server);
#   dev:    the client SDK: static libraries, headers, densemapConfig.cmake with the exported
#           targets densemap::client, densemap::io, densemap::map, ... (package libdensemap-dev).
# The SDK alone into any prefix: cmake --install build --component dev --prefix /opt/densemap
include(GNUInstallDirs)
include(CMakePackageConfigHelpers)

set(DENSEMAP_CMAKE_DIR ${CMAKE_INSTALL_LIBDIR}/cmake/densemap)

# The two SDK libraries and everything they link, as static libraries; exported as
# densemap::<name>. densemap::client reads (core/query, the snapshot files) and talks DDS; it
# links no engine and no TBB (scripts/check-packages.sh checks its link line).
# densemap::mapper is the engine in the caller's process: raycast, kernel maps, upsample,
# pipeline, TBB.
set(DENSEMAP_SDK_TARGETS
    densemap_options densemap_geometry densemap_traversal densemap_map densemap_query
    densemap_planner
    densemap_kernel_evidence densemap_io densemap_snapshot_proto densemap_store densemap_dds_msgs
    densemap_wire densemap_client
    densemap_parallel densemap_kernel densemap_raycast densemap_iln_proto densemap_upsample
    densemap_pipeline densemap_mapper)
# The SDK's headers: the client's and the mapper's public API and the plain types they name,
# nothing more (no DDS, protobuf, TBB or map internals; scripts/check-packages.sh checks it).
set(DENSEMAP_SDK_HEADERS
    client/include/densemap/client/client.hpp
    client/include/densemap/client/map_snapshot.hpp
    mapper/include/densemap/mapper/mapper.hpp
    core/map/include/densemap/map/sensor_model.hpp
    core/map/include/densemap/map/decay_options.hpp
    core/geometry/include/densemap/geometry/error.hpp
    core/geometry/include/densemap/geometry/point_cloud.hpp
    core/geometry/include/densemap/geometry/voxel_key.hpp
    core/io/include/densemap/io/raw_scan.hpp
    core/map/include/densemap/map/cell_change.hpp
    core/query/include/densemap/query/cell_state.hpp
    core/planner/include/densemap/planner/planner_types.hpp
    wire/include/densemap/wire/security.hpp
    wire/include/densemap/wire/server_status.hpp)
foreach(target IN LISTS DENSEMAP_SDK_TARGETS)
  string(REGEX REPLACE "^densemap_" "" export_name ${target})
  set_target_properties(${target} PROPERTIES EXPORT_NAME ${export_name})
endforeach()
install(TARGETS ${DENSEMAP_SDK_TARGETS} EXPORT densemapTargets
        ARCHIVE DESTINATION ${CMAKE_INSTALL_LIBDIR} COMPONENT dev
        INCLUDES DESTINATION ${CMAKE_INSTALL_INCLUDEDIR})
foreach(header IN LISTS DENSEMAP_SDK_HEADERS)
  string(REGEX REPLACE "^.*/include/(densemap/.*)/[^/]+$" "\\1" subdir ${header})
  install(FILES ${PROJECT_SOURCE_DIR}/${header}
          DESTINATION ${CMAKE_INSTALL_INCLUDEDIR}/${subdir} COMPONENT dev)
endforeach()
install(EXPORT densemapTargets NAMESPACE densemap:: DESTINATION ${DENSEMAP_CMAKE_DIR}
        COMPONENT dev)
configure_package_config_file(${PROJECT_SOURCE_DIR}/cmake/densemapConfig.cmake.in
                              ${PROJECT_BINARY_DIR}/densemapConfig.cmake
                              INSTALL_DESTINATION ${DENSEMAP_CMAKE_DIR})
write_basic_package_version_file(${PROJECT_BINARY_DIR}/densemapConfigVersion.cmake
                                 COMPATIBILITY SameMinorVersion)
install(FILES ${PROJECT_BINARY_DIR}/densemapConfig.cmake
              ${PROJECT_BINARY_DIR}/densemapConfigVersion.cmake
        DESTINATION ${DENSEMAP_CMAKE_DIR} COMPONENT dev)

# The server's files, laid out for the Debian package (prefix /usr): programs in bin/ (each
# add_executable installs itself with COMPONENT server), the ILN model in share/densemap, and the
# system paths Debian uses: /etc/densemap, /var/lib/densemap, /lib/systemd/system. The packaged
# config is config/densemap.textproto with its two relative paths made absolute: the snapshot in
# the state directory, the model under /usr/share.
set(DENSEMAP_PACKAGE_PREFIX /usr)
set(DENSEMAP_STATE_DIR /var/lib/densemap)
set(DENSEMAP_SYSCONF_DIR /etc/densemap)
set(DENSEMAP_SHARE_DIR ${DENSEMAP_PACKAGE_PREFIX}/share/densemap)
set(DENSEMAP_DOC_DIR ${DENSEMAP_PACKAGE_PREFIX}/share/doc/densemap-server)
set(DENSEMAP_SERVER_BIN ${DENSEMAP_PACKAGE_PREFIX}/bin/densemap-server)
file(READ ${PROJECT_SOURCE_DIR}/config/densemap.textproto DENSEMAP_PACKAGED_CONFIG)
foreach(pair "path: \"densemap.dmap\"|path: \"${DENSEMAP_STATE_DIR}/densemap.dmap\""
             "model: \"models/iln.pb\"|model: \"${DENSEMAP_SHARE_DIR}/models/iln.pb\"")
  string(REPLACE "|" ";" pair "${pair}")
  list(GET pair 0 from)
  list(GET pair 1 to)
  string(FIND "${DENSEMAP_PACKAGED_CONFIG}" "${from}" found)
  if(found LESS 0)
    message(FATAL_ERROR "config/densemap.textproto no longer contains '${from}'; update ${CMAKE_CURRENT_LIST_FILE}")
  endif()
  string(REPLACE "${from}" "${to}" DENSEMAP_PACKAGED_CONFIG "${DENSEMAP_PACKAGED_CONFIG}")
endforeach()
file(WRITE ${PROJECT_BINARY_DIR}/packaging/densemap.textproto "${DENSEMAP_PACKAGED_CONFIG}")
if(SYSTEMD_FOUND)
  set(DENSEMAP_SERVICE_TYPE "Type=notify\nNotifyAccess=main\nWatchdogSec=30")
else()
  set(DENSEMAP_SERVICE_TYPE "Type=simple")
endif()
string(REPLACE "\\n" "\n" DENSEMAP_SERVICE_TYPE "${DENSEMAP_SERVICE_TYPE}")
configure_file(${PROJECT_SOURCE_DIR}/config/densemap-server.service.in
               ${PROJECT_BINARY_DIR}/packaging/densemap-server.service @ONLY)
install(FILES ${PROJECT_BINARY_DIR}/packaging/densemap.textproto
        DESTINATION ${DENSEMAP_SYSCONF_DIR} COMPONENT server)
install(FILES ${PROJECT_BINARY_DIR}/packaging/densemap-server.service
        DESTINATION /lib/systemd/system COMPONENT server)
install(FILES ${PROJECT_SOURCE_DIR}/models/iln.pb DESTINATION share/densemap/models
        COMPONENT server)
install(DIRECTORY ${PROJECT_SOURCE_DIR}/config/load ${PROJECT_SOURCE_DIR}/config/sensors
        DESTINATION share/densemap/config COMPONENT server)
install(DIRECTORY DESTINATION ${DENSEMAP_STATE_DIR} COMPONENT server)
# The DDS Security PKI maker (docs/security.md).
# Installed with its version filled in (--version; its man page reads it).
set(DENSEMAP_VERSION ${PROJECT_VERSION})
configure_file(${PROJECT_SOURCE_DIR}/scripts/make-pki.sh
               ${PROJECT_BINARY_DIR}/packaging/densemap-make-pki @ONLY)
install(PROGRAMS ${PROJECT_BINARY_DIR}/packaging/densemap-make-pki DESTINATION bin
        COMPONENT server)
