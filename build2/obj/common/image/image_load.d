build2/obj/common/image/image_load.o: common/image/image_load.c \
 common/image/image_load.h common/base/asset.h common/image/mip.h \
 common/base/vec.h common/image/hdr.h common/image/imgio.h \
 common/base/log.h
common/image/image_load.h:
common/base/asset.h:
common/image/mip.h:
common/base/vec.h:
common/image/hdr.h:
common/image/imgio.h:
common/base/log.h:
