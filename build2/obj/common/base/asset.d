build2/obj/common/base/asset.o: common/base/asset.c common/base/asset.h \
 common/base/log.h
common/base/asset.h:
common/base/log.h:
