# Debian packages with CPack: `cd build && cpack -G DEB` (scripts/package.sh) writes
#   densemap-server_<version>_<arch>.deb   the server component (DensemapInstall.cmake)
#   libdensemap-dev_<version>_<arch>.deb   the dev component: the SDK (client and mapper)
#   python3-densemap_<version>_<arch>.deb  the python component: import densemap
# Each carries the copyright and changelog files Debian policy asks for, stripped binaries and
# its dependencies: shared libraries found by dpkg-shlibdeps for the server, the -dev packages
# of the SDK's dependencies for libdensemap-dev.
# The Maintainer field (and the changelog's signature): set it for a release,
# cmake -DDENSEMAP_MAINTAINER="Name <address>".
set(DENSEMAP_MAINTAINER "densemap maintainers <densemap-maintainers@example.org>"
    CACHE STRING "The packages' Maintainer field: Name <address>")
if(NOT DENSEMAP_MAINTAINER MATCHES "^[^<>]+ <[^<>@ ]+@[^<>@ ]+>$")
  message(FATAL_ERROR "DENSEMAP_MAINTAINER must read 'Name <address>', got '${DENSEMAP_MAINTAINER}'")
endif()
set(DENSEMAP_DEB_DIR ${PROJECT_SOURCE_DIR}/cmake/debian)
set(DENSEMAP_DEB_PACKAGES densemap-server libdensemap-dev)
if(DENSEMAP_BUILD_PYTHON)
  list(APPEND DENSEMAP_DEB_PACKAGES python3-densemap)
endif()
foreach(package IN LISTS DENSEMAP_DEB_PACKAGES)
  if(package STREQUAL densemap-server)
    set(component server)
  elseif(package STREQUAL python3-densemap)
    set(component python)
  else()
    set(component dev)
  endif()
  set(doc_dir ${CMAKE_INSTALL_DATADIR}/doc/${package})
  install(FILES ${DENSEMAP_DEB_DIR}/copyright DESTINATION ${doc_dir} COMPONENT ${component})
  # Debian wants the changelog compressed with gzip -9n (no name or time: reproducible).
  set(changelog ${PROJECT_BINARY_DIR}/packaging/${package}/changelog.Debian)
  configure_file(${DENSEMAP_DEB_DIR}/changelog.Debian.in ${changelog} @ONLY)
  add_custom_command(OUTPUT ${changelog}.gz COMMAND gzip -9nf -k ${changelog}
                     DEPENDS ${changelog} VERBATIM)
  add_custom_target(densemap_changelog_${component} ALL DEPENDS ${changelog}.gz)
  install(FILES ${changelog}.gz DESTINATION ${doc_dir} COMPONENT ${component})
endforeach()
install(FILES ${PROJECT_SOURCE_DIR}/README.md DESTINATION ${CMAKE_INSTALL_DATADIR}/doc/densemap-server
        COMPONENT server)
# The manual beside the README, so its links resolve where the package puts it.
install(DIRECTORY ${PROJECT_SOURCE_DIR}/docs DESTINATION ${CMAKE_INSTALL_DATADIR}/doc/densemap-server
        COMPONENT server)

set(CPACK_GENERATOR DEB)
set(CPACK_PACKAGE_NAME densemap)
set(CPACK_PACKAGE_VENDOR "densemap developers")
set(CPACK_PACKAGE_CONTACT "${DENSEMAP_MAINTAINER}")
set(CPACK_DEBIAN_PACKAGE_MAINTAINER "${DENSEMAP_MAINTAINER}")
set(CPACK_PACKAGE_VERSION ${PROJECT_VERSION})
# A Debian revision: packaged from upstream sources, not a native Debian package.
set(CPACK_DEBIAN_PACKAGE_RELEASE 1)
set(CPACK_PACKAGING_INSTALL_PREFIX /usr)
set(CPACK_STRIP_FILES ON)
set(CPACK_PRE_BUILD_SCRIPTS ${PROJECT_SOURCE_DIR}/cmake/DensemapStripArchives.cmake)
set(CPACK_COMPONENTS_ALL server dev)
if(DENSEMAP_BUILD_PYTHON)
  list(APPEND CPACK_COMPONENTS_ALL python)
endif()
set(CPACK_DEB_COMPONENT_INSTALL ON)
set(CPACK_DEBIAN_FILE_NAME DEB-DEFAULT)
set(CPACK_DEBIAN_PACKAGE_SECTION science)
set(CPACK_DEBIAN_PACKAGE_PRIORITY optional)
set(CPACK_DEBIAN_PACKAGE_HOMEPAGE "https://example.org/densemap")
set(CPACK_DEBIAN_SERVER_PACKAGE_NAME densemap-server)
set(CPACK_DEBIAN_SERVER_PACKAGE_SHLIBDEPS ON)
set(CPACK_DEBIAN_SERVER_PACKAGE_DEPENDS "adduser")
set(CPACK_COMPONENT_SERVER_DESCRIPTION "real-time occupancy-mapping server over DDS
densemap-server keeps a dense 3D occupancy map of LiDAR scans current at
sensor rate and answers queries over Cyclone DDS (loopback by default). The
densemap client, densemap-map (maps identical to OctoMap's graph2tree),
densemap-sim and the benchmarks come with it. Config in /etc/densemap, state
in /var/lib/densemap, systemd unit densemap-server.service.")
set(CPACK_DEBIAN_SERVER_PACKAGE_CONTROL_EXTRA
    ${DENSEMAP_DEB_DIR}/postinst ${DENSEMAP_DEB_DIR}/conffiles)
set(CPACK_DEBIAN_SERVER_PACKAGE_CONTROL_STRICT_PERMISSION ON)
set(CPACK_DEBIAN_DEV_PACKAGE_NAME libdensemap-dev)
set(CPACK_DEBIAN_DEV_PACKAGE_SECTION libdevel)
set(CPACK_DEBIAN_DEV_PACKAGE_DEPENDS
    "liboctomap-dev, libtbb-dev, libeigen3-dev, cyclonedds-dev, libprotobuf-dev, libbz2-dev, zlib1g-dev")
set(CPACK_COMPONENT_DEV_DESCRIPTION "SDK of the densemap occupancy-mapping server and library
Static libraries, headers and a CMake package (find_package(densemap)):
densemap::client for programs that publish scans to densemap-server, query
its map and fetch snapshots over DDS; densemap::mapper for programs that
build maps themselves (the server's engine, exact to OctoMap) and read and
write densemap's and OctoMap's map files.")
# The Python module in Debian's dist-packages for the python3 it was built with; its shared
# libraries (TBB, Cyclone DDS, protobuf, OctoMap) found by dpkg-shlibdeps.
set(CPACK_DEBIAN_PYTHON_PACKAGE_NAME python3-densemap)
set(CPACK_DEBIAN_PYTHON_PACKAGE_SECTION python)
set(CPACK_DEBIAN_PYTHON_PACKAGE_SHLIBDEPS ON)
set(CPACK_DEBIAN_PYTHON_PACKAGE_DEPENDS
    "python3 (>= ${Python_VERSION_MAJOR}.${Python_VERSION_MINOR}), python3 (<< ${Python_VERSION_MAJOR}.${DENSEMAP_PYTHON_NEXT_MINOR}), python3-numpy")
set(CPACK_COMPONENT_PYTHON_DESCRIPTION "Python module of the densemap occupancy mapper
import densemap: build exact 3D occupancy maps of LiDAR scans in your
process (densemap.Mapper: OctoMap's map cell for cell, many times faster,
or a dense kernel map) from NumPy arrays, query them in batches, save them
as .dmap or OctoMap files; read recordings (datasets, OctoMap files, ROS 2
bags) one scan at a time; talk to a running densemap-server
(densemap.Client).")
include(CPack)
