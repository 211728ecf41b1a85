# Debian packages (`cpack -G DEB` in the build folder):
#   softid-client  the `softid` client and the API's .proto files (share/softid/proto)
#   softid-server  `softid-server` and `softid-lab`
# Their dependencies come from dpkg-shlibdeps (the libraries the binaries load), so the packages
# install with apt on a bookworm machine that has none of the build's -dev packages.
set(CPACK_GENERATOR "DEB")
set(CPACK_PACKAGE_NAME "softid")
set(CPACK_PACKAGE_VENDOR "softid")
set(CPACK_PACKAGE_CONTACT "softid maintainers <softid@localhost>")
set(CPACK_PACKAGE_VERSION "${PROJECT_VERSION}")
set(CPACK_PACKAGE_DESCRIPTION_SUMMARY
    "material parameters of soft objects from depth images, without correspondences")
set(CPACK_STRIP_FILES ON)
set(CPACK_DEB_COMPONENT_INSTALL ON)
set(CPACK_DEBIAN_FILE_NAME DEB-DEFAULT)
set(CPACK_DEBIAN_PACKAGE_SHLIBDEPS ON)
set(CPACK_DEBIAN_PACKAGE_SECTION "science")
set(CPACK_DEBIAN_CLIENT_PACKAGE_NAME "softid-client")
set(CPACK_DEBIAN_SERVER_PACKAGE_NAME "softid-server")
set(CPACK_COMPONENT_CLIENT_DESCRIPTION
    "softid client for capture stations: uploads depth captures and fetches results")
set(CPACK_COMPONENT_SERVER_DESCRIPTION
    "softid job server and lab tool: fits material parameters to depth captures")
if(SOFTID_CLIENT_ONLY)
  set(CPACK_COMPONENTS_ALL client)
else()
  set(CPACK_COMPONENTS_ALL client server)
endif()
include(CPack)
