# CPack pre-build script: strips the debug information from the static libraries staged for
# libdensemap-dev, as Debian's dh_strip does for -dev packages (CPACK_STRIP_FILES only strips
# programs and shared libraries). 95 MB of archives become a few MB.
file(GLOB_RECURSE archives "${CPACK_TEMPORARY_INSTALL_DIRECTORY}/*.a")
foreach(archive IN LISTS archives)
  execute_process(COMMAND strip --strip-debug --enable-deterministic-archives "${archive}"
                  RESULT_VARIABLE result)
  if(NOT result EQUAL 0)
    message(FATAL_ERROR "strip --strip-debug ${archive} failed")
  endif()
endforeach()
