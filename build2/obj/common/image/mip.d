build2/obj/common/image/mip.o: common/image/mip.c common/image/mip.h \
 common/base/vec.h common/base/log.h
common/image/mip.h:
common/base/vec.h:
common/base/log.h:
