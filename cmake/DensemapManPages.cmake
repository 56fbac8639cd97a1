# A man page for every installed program (lintian's no-manual-page), made by
# help2man from the program's own --help, so the page and the program never disagree.
# help2man comes from scripts/install-deps.sh; without it the packages have no man pages (and
# scripts/check-packages.sh fails on lintian's no-manual-page).
find_program(DENSEMAP_HELP2MAN help2man)
if(NOT DENSEMAP_HELP2MAN)
  message(WARNING "help2man not found (scripts/install-deps.sh installs it): no man pages")
  return()
endif()
set(DENSEMAP_MAN_DIR ${PROJECT_BINARY_DIR}/man)
file(MAKE_DIRECTORY ${DENSEMAP_MAN_DIR})

# densemap_man_page(NAME COMMAND DESCRIPTION DEPENDS...): NAME.1.gz from `COMMAND --help`.
function(densemap_man_page name command description)
  set(page ${DENSEMAP_MAN_DIR}/${name}.1)
  add_custom_command(
    OUTPUT ${page}.gz
    COMMAND ${DENSEMAP_HELP2MAN} --no-info --no-discard-stderr
            --version-string=${PROJECT_VERSION} --name=${description}
            --source=densemap --section=1 --output=${page} ${command}
    # Debian wants man pages compressed with gzip -9n (no name or time: reproducible).
    COMMAND gzip -9nf ${page}
    DEPENDS ${ARGN}
    VERBATIM)
  add_custom_target(densemap_man_${name} ALL DEPENDS ${page}.gz)
  install(FILES ${page}.gz DESTINATION ${CMAKE_INSTALL_MANDIR}/man1 COMPONENT server)
endfunction()

densemap_man_page(densemap-server $<TARGET_FILE:densemap-server>
                  "real-time occupancy-mapping server over DDS" densemap-server)
densemap_man_page(densemap $<TARGET_FILE:densemap>
                  "client of densemap-server: replay, queries, snapshots, status, load tests"
                  densemap)
densemap_man_page(densemap-make-pki ${PROJECT_BINARY_DIR}/packaging/densemap-make-pki
                  "make a DDS Security PKI for densemap-server and its clients"
                  ${PROJECT_BINARY_DIR}/packaging/densemap-make-pki)
if(DENSEMAP_BUILD_TOOLS)
  densemap_man_page(densemap-map $<TARGET_FILE:densemap-map>
                    "build an occupancy map from a dataset (OctoMap's graph2tree, exact)"
                    densemap-map)
  densemap_man_page(densemap-sim $<TARGET_FILE:densemap-sim>
                    "simulate LiDAR scans of a scene, with poses and ground truth" densemap-sim)
  densemap_man_page(densemap-bench $<TARGET_FILE:densemap-bench>
                    "benchmark densemap's integration methods against OctoMap" densemap-bench)
  densemap_man_page(densemap-eval $<TARGET_FILE:densemap-eval>
                    "accuracy of occupancy and kernel maps against ground truth" densemap-eval)
  densemap_man_page(densemap-upsample-eval $<TARGET_FILE:densemap-upsample-eval>
                    "accuracy of LiDAR range-image upsampling (ILN, bilinear, nearest)"
                    densemap-upsample-eval)
endif()
