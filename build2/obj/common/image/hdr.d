build2/obj/common/image/hdr.o: common/image/hdr.c common/image/hdr.h \
 common/base/log.h common/image/mip.h common/base/vec.h
common/image/hdr.h:
common/base/log.h:
common/image/mip.h:
common/base/vec.h:
