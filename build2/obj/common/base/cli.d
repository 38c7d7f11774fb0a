build2/obj/common/base/cli.o: common/base/cli.c common/base/cli.h \
 common/base/log.h
common/base/cli.h:
common/base/log.h:
